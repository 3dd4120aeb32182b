//! The contract between each WGSL kernel and its CPU twin, checked without a
//! GPU: every shader is parsed with naga (wgpu's own front end) and its
//! constants, workgroup size, struct layouts (size, member names and byte
//! offsets under WGSL's layout rules) and bindings are compared with the
//! Rust side. This replaces trusting the "keep in sync" comments.

use naga::proc::Layouter;
use naga::{Expression, Literal, Module, TypeInner};
use tirewear::kpi::cpu::energy_map as em;
use tirewear::kpi::cpu::roughness_window::HANN_RMS;
use tirewear::kpi::cpu::telemetry_reduce::{
    CARCASS_PRESSURE_PA, CHUNK, ITEMS, ReduceChunk, ReduceRef, ReduceSample, SUMS, WG_SIZE,
};
use tirewear::kpi::energy_maps::{SLIDING_SPEED_BINS, T_INNER_BINS, T_SURFACE_BINS};
use tirewear::kpi::roughness_batch::{FFT_N, MOMENT_SUMS, PsdProfile, RoughChunk, Segment};

fn shader_text(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("shaders")
        .join(name);
    std::fs::read_to_string(&path).unwrap()
}

fn parse(name: &str, text: &str) -> Module {
    naga::front::wgsl::parse_str(text)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(text)))
}

fn shader(name: &str) -> Module {
    parse(name, &shader_text(name))
}

/// A chunk kernel as the host builds it (`chunk_shader!`): shared.wgsl, then
/// the kernel's file. A record the kernel defined again would not parse.
fn chunk_shader(name: &str) -> Module {
    parse(name, &(shader_text("shared.wgsl") + &shader_text(name)))
}

/// The value of a scalar `const` of the module (as f64).
fn constant(m: &Module, name: &str) -> f64 {
    let c = m
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no const {name}"))
        .1;
    match &m.global_expressions[c.init] {
        Expression::Literal(l) => match *l {
            Literal::U32(v) => v as f64,
            Literal::I32(v) => v as f64,
            Literal::F32(v) => v as f64,
            Literal::AbstractInt(v) => v as f64,
            Literal::AbstractFloat(v) => v,
            ref other => panic!("const {name}: {other:?}"),
        },
        other => panic!("const {name} is not a literal: {other:?}"),
    }
}

/// A member type as Rust spells it: `f32`, `u32`, `[f32; 8]`.
fn rust_spelling(m: &Module, ty: naga::Handle<naga::Type>) -> String {
    match &m.types[ty].inner {
        TypeInner::Scalar(s) => match (s.kind, s.width) {
            (naga::ScalarKind::Float, 4) => "f32".into(),
            (naga::ScalarKind::Uint, 4) => "u32".into(),
            (naga::ScalarKind::Sint, 4) => "i32".into(),
            other => format!("{other:?}"),
        },
        TypeInner::Array {
            base,
            size: naga::ArraySize::Constant(n),
            ..
        } => format!("[{}; {n}]", rust_spelling(m, *base)),
        other => format!("{other:?}"),
    }
}

/// (size, [(member, type, offset)]) of a WGSL struct under WGSL's layout rules.
fn wgsl_struct(m: &Module, name: &str) -> (u32, Vec<(String, String, u32)>) {
    let mut layouter = Layouter::default();
    layouter.update(m.to_ctx()).unwrap();
    let (h, ty) = m
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no struct {name}"));
    let TypeInner::Struct { members, .. } = &ty.inner else {
        panic!("{name} is not a struct");
    };
    (
        layouter[h].size,
        members
            .iter()
            .map(|mb| {
                (
                    mb.name.clone().unwrap_or_default(),
                    rust_spelling(m, mb.ty),
                    mb.offset,
                )
            })
            .collect(),
    )
}

/// (size, [(field, type, offset)]) of a `repr(C)` Rust struct; each field's
/// stated type is checked by the compiler (the accessor must type-check).
macro_rules! rust_struct {
    ($t:ty, [$($f:ident: $ft:ty),* $(,)?]) => {{
        $(let _: fn(&$t) -> &$ft = |s| &s.$f;)*
        (
            std::mem::size_of::<$t>() as u32,
            vec![$((
                stringify!($f).to_string(),
                stringify!($ft).to_string(),
                std::mem::offset_of!($t, $f) as u32,
            )),*],
        )
    }};
}

/// The workgroup size of the module's single entry point.
fn workgroup_size(m: &Module) -> [u32; 3] {
    assert_eq!(m.entry_points.len(), 1);
    m.entry_points[0].workgroup_size
}

/// Bindings of the module's resources, in binding order: they must be
/// group 0, bindings 0..n without gaps (the dispatch code binds buffers in
/// that order).
fn bindings(m: &Module) -> Vec<(u32, String)> {
    let mut b: Vec<(u32, String)> = m
        .global_variables
        .iter()
        .filter_map(|(_, g)| {
            g.binding.as_ref().map(|rb| {
                assert_eq!(rb.group, 0, "{:?}", g.name);
                (rb.binding, g.name.clone().unwrap_or_default())
            })
        })
        .collect();
    b.sort();
    for (i, (k, _)) in b.iter().enumerate() {
        assert_eq!(*k as usize, i, "binding gap at {i}: {b:?}");
    }
    b
}

fn names(b: &[(u32, String)]) -> Vec<&str> {
    b.iter().map(|(_, n)| n.as_str()).collect()
}

#[test]
fn telemetry_reduce_matches_its_cpu_twin() {
    let m = chunk_shader("telemetry_reduce.wgsl");
    assert_eq!(constant(&m, "WG_SIZE"), WG_SIZE as f64);
    assert_eq!(constant(&m, "ITEMS"), ITEMS as f64);
    assert_eq!(constant(&m, "SUMS"), SUMS as f64);
    assert_eq!(
        constant(&m, "CARCASS_PRESSURE_PA"),
        CARCASS_PRESSURE_PA as f64
    );
    assert_eq!(workgroup_size(&m), [WG_SIZE as u32, 1, 1]);
    let sample = rust_struct!(
        ReduceSample,
        [
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
            t_surface_rate: f32,
            t_inner_rate: f32,
            load_rel: f32,
            time_s: f32,
            distance_m: f32,
            accel_x: f32,
            accel_y: f32,
            dt: f32,
            dt_lo: f32,
        ]
    );
    assert_eq!(wgsl_struct(&m, "Sample"), sample);
    assert_eq!(
        wgsl_struct(&m, "Chunk"),
        rust_struct!(ReduceChunk, [start: u32, count: u32, wheel: u32, pad: u32])
    );
    assert_eq!(
        wgsl_struct(&m, "Reference"),
        rust_struct!(ReduceRef, [v: [f32; 8]])
    );
    assert_eq!(
        names(&bindings(&m)),
        ["samples", "chunks", "refs", "partials"]
    );
}

#[test]
fn energy_map_matches_its_cpu_twin() {
    let m = chunk_shader("energy_map.wgsl");
    assert_eq!(constant(&m, "WG_SIZE"), WG_SIZE as f64);
    assert_eq!(constant(&m, "ITEMS"), ITEMS as f64);
    assert_eq!(constant(&m, "CHUNK"), CHUNK as f64);
    assert_eq!(workgroup_size(&m), [WG_SIZE as u32, 1, 1]);
    for (prefix, bins) in [
        ("T_SURFACE", T_SURFACE_BINS),
        ("T_INNER", T_INNER_BINS),
        ("SPEED", SLIDING_SPEED_BINS),
    ] {
        assert_eq!(constant(&m, &format!("{prefix}_LO")), bins.lo, "{prefix}");
        assert_eq!(
            constant(&m, &format!("{prefix}_WIDTH")),
            bins.width,
            "{prefix}"
        );
        assert_eq!(
            constant(&m, &format!("{prefix}_N")),
            bins.n as f64,
            "{prefix}"
        );
    }
    assert_eq!(
        constant(&m, "SURFACE_INNER_BINS"),
        em::SURFACE_INNER_BINS as f64
    );
    assert_eq!(constant(&m, "LATERAL_BINS_AT"), em::LATERAL_BINS_AT as f64);
    assert_eq!(constant(&m, "BINS"), em::BINS as f64);
    assert_eq!(constant(&m, "ENERGY_QUANTA_PER_J"), em::ENERGY_QUANTA_PER_J);
    assert_eq!(names(&bindings(&m)), ["samples", "chunks", "maps"]);
    // The private histogram: BINS (lo, hi) u32 pairs, inside WebGPU's
    // default 16 KiB of workgroup memory.
    assert_eq!(workgroup_bytes(&m), 2 * 4 * em::BINS as u32);
    assert!(workgroup_bytes(&m) <= 16384);
}

#[test]
fn condition_map_matches_its_cpu_twin() {
    use tirewear::kpi::cpu::condition_map as cm;
    let m = chunk_shader("condition_map.wgsl");
    assert_eq!(constant(&m, "WG_SIZE"), WG_SIZE as f64);
    assert_eq!(constant(&m, "ITEMS"), ITEMS as f64);
    assert_eq!(workgroup_size(&m), [WG_SIZE as u32, 1, 1]);
    assert_eq!(constant(&m, "N_CONDITIONS"), cm::N_CONDITIONS as f64);
    assert_eq!(constant(&m, "N_PAIRS"), cm::N_PAIRS as f64);
    assert_eq!(constant(&m, "CONDITION_BINS"), cm::CONDITION_BINS as f64);
    assert_eq!(constant(&m, "PAIR_BINS"), cm::PAIR_BINS as f64);
    assert_eq!(constant(&m, "MAP_BINS"), cm::MAP_BINS as f64);
    assert_eq!(
        constant(&m, "SLIP_SPEED_FLOOR_MPS"),
        cm::SLIP_SPEED_FLOOR_MPS
    );
    assert_eq!(constant(&m, "LOAD_FLOOR_N"), cm::LOAD_FLOOR_N);
    assert_eq!(constant(&m, "ENERGY_QUANTA_PER_J"), em::ENERGY_QUANTA_PER_J);
    assert_eq!(
        wgsl_struct(&m, "ConditionBins"),
        rust_struct!(cm::ConditionBins, [lo: f32, inv_width: f32, n: u32, offset: u32, value: u32])
    );
    assert_eq!(
        names(&bindings(&m)),
        ["samples", "chunks", "conditions", "maps"]
    );
    assert_eq!(workgroup_bytes(&m), 2 * 4 * cm::MAP_BINS as u32);
    assert!(workgroup_bytes(&m) <= 16384);
}

/// Bytes of workgroup memory a module declares.
fn workgroup_bytes(m: &Module) -> u32 {
    let mut layouter = Layouter::default();
    layouter.update(m.to_ctx()).unwrap();
    m.global_variables
        .iter()
        .filter(|(_, v)| v.space == naga::AddressSpace::WorkGroup)
        .map(|(_, v)| layouter[v.ty].size)
        .sum()
}

#[test]
fn roughness_kernels_match_their_cpu_twins() {
    let chunk = rust_struct!(RoughChunk, [start: u32, count: u32, profile: u32, lag: u32]);
    for name in ["roughness_moments.wgsl", "roughness_hdc.wgsl"] {
        let m = shader(name);
        assert_eq!(constant(&m, "WG_SIZE"), WG_SIZE as f64, "{name}");
        assert_eq!(constant(&m, "ITEMS"), ITEMS as f64, "{name}");
        assert_eq!(workgroup_size(&m), [WG_SIZE as u32, 1, 1], "{name}");
        assert_eq!(wgsl_struct(&m, "Chunk"), chunk, "{name}");
        bindings(&m);
    }
    assert_eq!(
        constant(&shader("roughness_moments.wgsl"), "SUMS"),
        MOMENT_SUMS as f64
    );

    let w = shader("roughness_window.wgsl");
    assert_eq!(constant(&w, "N"), FFT_N as f64);
    assert_eq!(
        constant(&w, "ITEMS") * constant(&w, "WG_SIZE"),
        FFT_N as f64,
        "ITEMS = N / WG_SIZE"
    );
    assert_eq!(workgroup_size(&w)[0] as f64, constant(&w, "WG_SIZE"));
    // f32 in the shader: equal to the f64 constant rounded to f32.
    assert_eq!(constant(&w, "HANN_RMS"), HANN_RMS as f32 as f64);
    assert_eq!(
        wgsl_struct(&w, "Segment"),
        rust_struct!(Segment, [start: u32, profile: u32])
    );
    assert_eq!(names(&bindings(&w)), ["heights", "segments", "out"]);

    let p = shader("roughness_psd.wgsl");
    assert_eq!(constant(&p, "N"), FFT_N as f64);
    assert_eq!(constant(&p, "BINS"), (FFT_N / 2 + 1) as f64);
    assert_eq!(workgroup_size(&p)[0] as f64, constant(&p, "WG_SIZE"));
    assert_eq!(
        wgsl_struct(&p, "PsdProfile"),
        rust_struct!(PsdProfile, [seg_first: u32, seg_count: u32, dx_mm: f32, pad: u32])
    );
    assert_eq!(names(&bindings(&p)), ["spectra", "profiles", "psd"]);

    let f = shader("fft_pass.wgsl");
    assert_eq!(constant(&f, "N"), FFT_N as f64);
    assert_eq!(workgroup_size(&f)[0] as f64, constant(&f, "WG_SIZE"));
    assert_eq!(names(&bindings(&f)), ["pass_", "src", "dst", "twiddles"]);
}
