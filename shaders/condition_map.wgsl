// Condition energy maps: each sample's friction energy (total, longitudinal,
// lateral) binned by each per-sample condition (slip ratio, lateral slip, …),
// one 1-D map per condition, and one 2-D map of the total energy per pair of
// conditions on their coarse bins, accumulated into one set of maps per wheel.
// The bin table comes from the host (binding 2: src/kpi/cpu/condition_map.rs is
// its only definition); the conditions are computed here in the table's
// order. Sums are exact 64-bit fixed-point quanta, as in energy_map.wgsl:
// a private histogram per workgroup, then its non-zero bins added to the
// wheel's maps. The 1-D maps sum the longitudinal and lateral parts only;
// the host takes a bin's total as their sum.
// CPU twin: src/kpi/cpu/condition_map.rs; chunks and samples are those of
// telemetry_reduce.

// shared.wgsl (prepended by the host): WG_SIZE, ITEMS, Sample, Chunk,
// ENERGY_QUANTA_PER_J, to_quanta, carried.

// Must match src/kpi/cpu/condition_map.rs (checked by tests/shader_contract.rs).
const N_CONDITIONS: u32 = 19u;
const N_PAIRS: u32 = 8u;
const CONDITION_BINS: u32 = 508u; // 1-D bins of one component over all conditions
const PAIR_BINS: u32 = 512u; // 2-D cells over all pairs (total energy only)
const MAP_BINS: u32 = 1528u; // longitudinal, lateral CONDITION_BINS, then PAIR_BINS
const SLIP_SPEED_FLOOR_MPS: f32 = 1.0;
const LOAD_FLOOR_N: f32 = 100.0;

// Must match ConditionBins (checked by tests/shader_contract.rs).
struct ConditionBins {
    lo: f32,
    inv_width: f32, // 1 / width
    n: u32,
    offset: u32, // first bin in a component's 1-D bins or in the pair cells (a pair's second axis: unused)
    value: u32, // which of condition_values it bins
}

@group(0) @binding(0) var<storage, read> samples: array<Sample>;
@group(0) @binding(1) var<storage, read> chunks: array<Chunk>;
// N_CONDITIONS 1-D entries, then each pair's two axes (first, second).
@group(0) @binding(2) var<storage, read> conditions: array<ConditionBins>;
// Per wheel, MAP_BINS (lo, hi) pairs: maps[2 * (wheel * MAP_BINS + bin) + {0, 1}].
@group(0) @binding(3) var<storage, read_write> maps: array<atomic<u32>>;

var<workgroup> bin_lo: array<atomic<u32>, MAP_BINS>;
var<workgroup> bin_hi: array<atomic<u32>, MAP_BINS>; // 11.9 KiB with bin_lo (limit 16 KiB)

// Equal-width bins clamped at both ends, NaN to bin 0; subtraction and
// multiplication only (correctly rounded), as ConditionBins::index.
fn bin_index(x: f32, b: ConditionBins) -> u32 {
    let i = floor((x - b.lo) * b.inv_width);
    if !(i >= 0.0) {
        return 0u;
    }
    return min(u32(i), b.n - 1u);
}

fn add_to_workgroup(bin: u32, q: vec2<u32>) {
    let old = atomicAdd(&bin_lo[bin], q.x);
    let hi = carried(old, q.x, q.y);
    if hi != 0u {
        atomicAdd(&bin_hi[bin], hi);
    }
}

// Two 64-bit quanta (lo, hi) added, wrapping as the host's u64.
fn add_quanta(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

fn add_to_map(slot: u32, lo: u32, hi: u32) {
    let old = atomicAdd(&maps[2u * slot], lo);
    let h = carried(old, lo, hi);
    if h != 0u {
        atomicAdd(&maps[2u * slot + 1u], h);
    }
}

// The conditions of one sample, in the order of CONDITIONS.
fn condition_values(p: Sample) -> array<f32, N_CONDITIONS> {
    let v_sx = p.vx - p.omega * p.radius; // eq. 21
    let v_sy = p.vy; // eq. 22
    let v_s = sqrt(v_sx * v_sx + v_sy * v_sy);
    let v_ref = max(abs(p.vx), SLIP_SPEED_FLOOR_MPS);
    let force = sqrt(p.fx * p.fx + p.fy * p.fy);
    return array<f32, N_CONDITIONS>(
        -v_sx / v_ref,
        p.vy / v_ref,
        v_s / v_ref,
        v_s,
        p.fz,
        force / max(p.fz, LOAD_FLOOR_N),
        p.t_surface,
        p.t_inner,
        p.pressure,
        p.camber,
        p.vx,
        0.5 * (p.t_surface + p.t_inner),
        p.t_surface_rate,
        p.t_inner_rate,
        p.load_rel,
        p.time_s,
        p.distance_m,
        p.accel_x,
        p.accel_y,
    );
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
    for (var b = lid; b < MAP_BINS; b += WG_SIZE) {
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
            let e_x = -p.fx * v_sx * p.dt; // eq. 23
            let e_y = -p.fy * v_sy * p.dt; // eq. 24
            let q_x = to_quanta(e_x);
            let q_y = to_quanta(e_y);
            let q_total = add_quanta(q_x, q_y);
            var values = condition_values(p); // var: indexed by a loop counter
            for (var c = 0u; c < N_CONDITIONS; c++) {
                let t = conditions[c];
                let b = t.offset + bin_index(values[t.value], t);
                add_to_workgroup(b, q_x);
                add_to_workgroup(CONDITION_BINS + b, q_y);
            }
            for (var pr = 0u; pr < N_PAIRS; pr++) {
                let ta = conditions[N_CONDITIONS + 2u * pr];
                let tb = conditions[N_CONDITIONS + 2u * pr + 1u];
                let ia = bin_index(values[ta.value], ta);
                let ib = bin_index(values[tb.value], tb);
                add_to_workgroup(2u * CONDITION_BINS + ta.offset + ia * tb.n + ib, q_total);
            }
        }
    }
    workgroupBarrier();
    // Phase 2: each thread adds the bins b ≡ lid (mod WG_SIZE) to the wheel's maps.
    if in_range {
        for (var b = lid; b < MAP_BINS; b += WG_SIZE) {
            let lo = atomicLoad(&bin_lo[b]);
            let hi = atomicLoad(&bin_hi[b]);
            if lo != 0u || hi != 0u {
                add_to_map(wheel * MAP_BINS + b, lo, hi);
            }
        }
    }
}
