// Definitions shared by the chunk kernels (telemetry_reduce, energy_map,
// condition_map): the host prepends this file to each of them
// (src/gpu/mod.rs, `chunk_shader!`), so each record and helper is written
// once. tests/shader_contract.rs checks every definition against Rust.

// Must match src/kpi/cpu/telemetry_reduce.rs (checked by tests/shader_contract.rs).
const WG_SIZE: u32 = 128u;
const ITEMS: u32 = 8u;
const CHUNK: u32 = 1024u;

// One kept sample. Must match ReduceSample (checked by tests/shader_contract.rs).
struct Sample {
    vx: f32,
    vy: f32,
    omega: f32,
    radius: f32,
    fx: f32,
    fy: f32,
    fz: f32,
    t_surface: f32,
    t_inner: f32,
    pressure: f32,
    camber: f32,
    // Derived by the host (ReduceSample): only condition_map reads them.
    t_surface_rate: f32, // K/s
    t_inner_rate: f32, // K/s
    load_rel: f32, // F_z / the wheel's mean F_z
    time_s: f32, // since the wheel's first kept sample
    distance_m: f32, // Σ v_x·Δt before this sample
    accel_x: f32, // dv_x/dt over ±0.5 s (m/s²)
    accel_y: f32, // |Σ F_y| / m of the car (m/s²)
    dt: f32,
    dt_lo: f32, // f64 remainder of dt, used by the CPU twins only
}

// One workgroup's slice of the samples. Must match ReduceChunk (checked by tests/shader_contract.rs).
struct Chunk {
    start: u32,
    count: u32,
    wheel: u32,
    pad: u32,
}

// Fixed-point energy sums (energy_map, condition_map). Must match
// src/kpi/cpu/energy_map.rs (checked by tests/shader_contract.rs).
const ENERGY_QUANTA_PER_J: f32 = 16777216.0; // 2^24: a quantum of 6e-8 J, sums up to 5.5e11 J

// round(e · ENERGY_QUANTA_PER_J) as a 64-bit two's-complement (lo, hi)
// (energy_map::to_quanta).
fn to_quanta(e: f32) -> vec2<u32> {
    let m = round(abs(e) * ENERGY_QUANTA_PER_J);
    let h = floor(m / 4294967296.0);
    var lo = u32(m - h * 4294967296.0);
    var hi = u32(h);
    if e < 0.0 {
        lo = ~lo + 1u;
        hi = ~hi + select(0u, 1u, lo == 0u);
    }
    return vec2<u32>(lo, hi);
}

// The high word to add after adding `lo` to a low word that held `old`:
// `hi` plus the carry out of the low word.
fn carried(old: u32, lo: u32, hi: u32) -> u32 {
    return hi + select(0u, 1u, old + lo < old);
}
