//! The CPU twins of the WGSL kernels in `shaders/`: one module per shader,
//! of the same name, written loop for loop like it (same workgroup size,
//! same buffer order), in f64 where the shader uses f32. They are the CPU
//! engine and the reference the GPU engine is tested against; the shader /
//! Rust contract (struct layouts, workgroup sizes, shared constants) is
//! checked with naga in `tests/shader_contract.rs`. Bindings of each
//! shader: docs/kpis.md, "Kernels and their bindings".

pub mod condition_map;
pub mod energy_map;
pub mod fft_pass;
pub mod roughness_hdc;
pub mod roughness_moments;
pub mod roughness_psd;
pub mod roughness_window;
pub mod telemetry_reduce;
