// Friction-energy maps: each sample's friction energy binned over
// (surface temperature × inner-liner temperature) and (sliding speed ×
// surface temperature), and its lateral part over (surface × inner-liner
// temperature), accumulated into one map per wheel.
//
// WGSL has no float atomics, so energies are added as fixed-point integers
// (ENERGY_QUANTA_PER_J quanta per joule, rounded per sample) into 64-bit
// two's-complement sums kept as (lo, hi) u32 pairs: a carry out of `lo` is
// detected from the value atomicAdd returns. Integer addition is exact and
// associative, so the sums do not depend on the order in which threads or
// workgroups add: the result is deterministic, and equal to the CPU twin's
// wherever the per-sample energies round to the same quantum.
//
// Each workgroup bins one chunk of one wheel into a private histogram in
// workgroup memory (phase 1), then adds its non-zero bins to the wheel's
// map in the output buffer (phase 2): one global atomic per touched bin and
// chunk instead of one partial map per chunk.
// CPU twin: src/kpi/cpu/energy_map.rs; chunks and samples are those of
// telemetry_reduce.

// shared.wgsl (prepended by the host): WG_SIZE, ITEMS, CHUNK, Sample, Chunk,
// ENERGY_QUANTA_PER_J, to_quanta, carried.

// Must match src/kpi/cpu/energy_map.rs and src/kpi/energy_maps.rs (bin edges) (checked by tests/shader_contract.rs).
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

@group(0) @binding(0) var<storage, read> samples: array<Sample>;
@group(0) @binding(1) var<storage, read> chunks: array<Chunk>;
// Per wheel, BINS (lo, hi) pairs: maps[2 * (wheel * BINS + bin) + {0, 1}].
@group(0) @binding(2) var<storage, read_write> maps: array<atomic<u32>>;

var<workgroup> bin_lo: array<atomic<u32>, BINS>;
var<workgroup> bin_hi: array<atomic<u32>, BINS>; // 13 KiB of workgroup memory in all

// Equal-width bins clamped at both ends; NaN goes to bin 0 (as Bins::index).
fn bin_index(x: f32, lo: f32, width: f32, n: u32) -> u32 {
    let i = floor((x - lo) / width);
    if !(i >= 0.0) {
        return 0u;
    }
    return min(u32(i), n - 1u);
}

fn add_to_workgroup(bin: u32, q: vec2<u32>) {
    let old = atomicAdd(&bin_lo[bin], q.x);
    let hi = carried(old, q.x, q.y);
    if hi != 0u {
        atomicAdd(&bin_hi[bin], hi);
    }
}

fn add_to_map(slot: u32, lo: u32, hi: u32) {
    let old = atomicAdd(&maps[2u * slot], lo);
    let h = carried(old, lo, hi);
    if h != 0u {
        atomicAdd(&maps[2u * slot + 1u], h);
    }
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
    var wheel = 0u;
    if in_range {
        count = chunks[c_index].count;
        start = chunks[c_index].start;
        wheel = chunks[c_index].wheel;
    }
    // Phase 0: clear the workgroup's histogram.
    for (var b = lid; b < BINS; b += WG_SIZE) {
        atomicStore(&bin_lo[b], 0u);
        atomicStore(&bin_hi[b], 0u);
    }
    workgroupBarrier();
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
            let a = s * T_INNER_N + i;
            let q = to_quanta(power * p.dt);
            add_to_workgroup(a, q);
            add_to_workgroup(SURFACE_INNER_BINS + v * T_SURFACE_N + s, q);
            add_to_workgroup(LATERAL_BINS_AT + a, to_quanta(-p.fy * v_sy * p.dt)); // eq. 24
        }
    }
    workgroupBarrier();
    // Phase 2: each thread adds the bins b ≡ lid (mod WG_SIZE) to the wheel's map.
    if in_range {
        for (var b = lid; b < BINS; b += WG_SIZE) {
            let lo = atomicLoad(&bin_lo[b]);
            let hi = atomicLoad(&bin_hi[b]);
            if lo != 0u || hi != 0u {
                add_to_map(wheel * BINS + b, lo, hi);
            }
        }
    }
}
