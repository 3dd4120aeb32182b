// Height moments of road profiles: per chunk of one profile, Σd, Σ|d|, Σd²,
// Σd³, Σd⁴ with d = z − ref(profile). Run with ref = the first height (for
// the mean), then with ref = the mean. CPU twin: src/kpi/cpu/roughness_moments.rs.

// Must match src/kpi/cpu/telemetry_reduce.rs (WG_SIZE, ITEMS) and (checked by tests/shader_contract.rs).
// src/kpi/roughness_batch.rs (MOMENT_SUMS, RoughChunk).
const WG_SIZE: u32 = 128u;
const ITEMS: u32 = 8u;
const SUMS: u32 = 5u;

struct Chunk {
    start: u32,
    count: u32,
    profile: u32,
    lag: u32,
}

@group(0) @binding(0) var<storage, read> heights: array<f32>;
@group(0) @binding(1) var<storage, read> chunks: array<Chunk>;
@group(0) @binding(2) var<storage, read> refs: array<f32>;
@group(0) @binding(3) var<storage, read_write> partials: array<f32>;

var<workgroup> acc: array<array<f32, SUMS>, WG_SIZE>;

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let c_index = wg.x + wg.y * nwg.x;
    let in_range = c_index < arrayLength(&chunks);
    var s: array<f32, SUMS>;
    if in_range {
        let c = chunks[c_index];
        let r = refs[c.profile];
        for (var k = 0u; k < ITEMS; k++) {
            let j = lid + k * WG_SIZE;
            if j < c.count {
                let d = heights[c.start + j] - r;
                let d2 = d * d;
                s[0] += d;
                s[1] += abs(d);
                s[2] += d2;
                s[3] += d2 * d;
                s[4] += d2 * d2;
            }
        }
    }
    acc[lid] = s;
    workgroupBarrier();
    for (var stride = WG_SIZE / 2u; stride > 0u; stride = stride / 2u) {
        if lid < stride {
            for (var m = 0u; m < SUMS; m++) {
                acc[lid][m] += acc[lid + stride][m];
            }
        }
        workgroupBarrier();
    }
    if in_range && lid == 0u {
        for (var m = 0u; m < SUMS; m++) {
            partials[c_index * SUMS + m] = acc[0][m];
        }
    }
}
