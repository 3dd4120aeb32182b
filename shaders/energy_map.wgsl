// Friction-energy maps: each sample's friction energy binned over
// (surface temperature × inner-liner temperature) and (sliding speed ×
// surface temperature), and its lateral part over (surface × inner-liner
// temperature), one partial map per chunk of one wheel. No float
// atomics in WGSL: every thread owns the bins b with b % WG_SIZE == lid and
// adds the chunk's samples in order, so each bin's sum is deterministic.
// CPU twin: src/kpi/energy_map_kernel.rs; chunks and samples are those of
// telemetry_reduce; partial maps are merged per wheel in f64 on the CPU.

// Must match src/kpi/energy_map_kernel.rs and src/kpi/energy_map.rs (bin edges) (checked by tests/shader_contract.rs).
const WG_SIZE: u32 = 128u;
const ITEMS: u32 = 8u;
const CHUNK: u32 = 1024u;
const T_SURFACE_LO: f32 = 20.0;
const T_SURFACE_WIDTH: f32 = 5.0;
const T_SURFACE_N: u32 = 24u;
const T_INNER_LO: f32 = 40.0;
const T_INNER_WIDTH: f32 = 5.0;
const T_INNER_N: u32 = 24u;
const SPEED_LO: f32 = 0.0;
const SPEED_WIDTH: f32 = 0.5;
const SPEED_N: u32 = 20u;
const SURFACE_INNER_BINS: u32 = 576u; // T_SURFACE_N * T_INNER_N
const LATERAL_BINS_AT: u32 = 1056u; // SURFACE_INNER_BINS + SPEED_N * T_SURFACE_N
const BINS: u32 = 1632u; // + SURFACE_INNER_BINS (lateral map)
const OWNED: u32 = 13u; // ceil(BINS / WG_SIZE)

// Must match ReduceSample (src/kpi/telemetry_reduce.rs) (checked by tests/shader_contract.rs).
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
    dt: f32,
    dt_lo: f32,
}

// Must match ReduceChunk (checked by tests/shader_contract.rs).
struct Chunk {
    start: u32,
    count: u32,
    wheel: u32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> samples: array<Sample>;
@group(0) @binding(1) var<storage, read> chunks: array<Chunk>;
@group(0) @binding(2) var<storage, read_write> partials: array<f32>;

var<workgroup> bin_a: array<u32, CHUNK>;
var<workgroup> bin_b: array<u32, CHUNK>;
var<workgroup> energy: array<f32, CHUNK>;
var<workgroup> energy_y: array<f32, CHUNK>; // 16 KiB of workgroup memory in all

// Equal-width bins clamped at both ends; NaN goes to bin 0 (as Bins::index).
fn bin_index(x: f32, lo: f32, width: f32, n: u32) -> u32 {
    let i = floor((x - lo) / width);
    if !(i >= 0.0) {
        return 0u;
    }
    return min(u32(i), n - 1u);
}

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let c_index = wg.x + wg.y * nwg.x;
    let in_range = c_index < arrayLength(&chunks);
    var count = 0u;
    var start = 0u;
    if in_range {
        count = chunks[c_index].count;
        start = chunks[c_index].start;
    }
    // Phase 1: each thread bins ITEMS samples (coalesced).
    for (var k = 0u; k < ITEMS; k++) {
        let j = lid + k * WG_SIZE;
        if j < count {
            let p = samples[start + j];
            let v_sx = p.vx - p.omega * p.radius; // eq. 21
            let v_sy = p.vy; // eq. 22
            let power = -p.fx * v_sx - p.fy * v_sy; // eqs. 23–25
            let s = bin_index(p.t_surface, T_SURFACE_LO, T_SURFACE_WIDTH, T_SURFACE_N);
            let i = bin_index(p.t_inner, T_INNER_LO, T_INNER_WIDTH, T_INNER_N);
            let v = bin_index(sqrt(v_sx * v_sx + v_sy * v_sy), SPEED_LO, SPEED_WIDTH, SPEED_N);
            bin_a[j] = s * T_INNER_N + i;
            bin_b[j] = SURFACE_INNER_BINS + v * T_SURFACE_N + s;
            energy[j] = power * p.dt;
            energy_y[j] = -p.fy * v_sy * p.dt; // eq. 24
        }
    }
    workgroupBarrier();
    // Phase 2: each thread sums the samples of the bins it owns, in sample order.
    var acc: array<f32, OWNED>;
    for (var j = 0u; j < count; j++) {
        let a = bin_a[j];
        if a % WG_SIZE == lid {
            acc[a / WG_SIZE] += energy[j];
        }
        let b = bin_b[j];
        if b % WG_SIZE == lid {
            acc[b / WG_SIZE] += energy[j];
        }
        let c = LATERAL_BINS_AT + a;
        if c % WG_SIZE == lid {
            acc[c / WG_SIZE] += energy_y[j];
        }
    }
    if in_range {
        for (var o = 0u; o < OWNED; o++) {
            let bin = o * WG_SIZE + lid;
            if bin < BINS {
                partials[c_index * BINS + bin] = acc[o];
            }
        }
    }
}
