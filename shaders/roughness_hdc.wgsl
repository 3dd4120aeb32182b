// Height-difference correlation of road profiles: per chunk (profile, lag k),
// Σ (z[i + k] − z[i])² over the chunk's i. CPU twin: src/kpi/cpu/roughness_hdc.rs.

// Must match src/kpi/cpu/telemetry_reduce.rs (WG_SIZE, ITEMS) and RoughChunk (checked by tests/shader_contract.rs).
const WG_SIZE: u32 = 128u;
const ITEMS: u32 = 8u;

struct Chunk {
    start: u32,
    count: u32,
    profile: u32,
    lag: u32,
}

@group(0) @binding(0) var<storage, read> heights: array<f32>;
@group(0) @binding(1) var<storage, read> chunks: array<Chunk>;
@group(0) @binding(2) var<storage, read_write> partials: array<f32>;

var<workgroup> acc: array<f32, WG_SIZE>;

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let c_index = wg.x + wg.y * nwg.x;
    let in_range = c_index < arrayLength(&chunks);
    var s = 0.0;
    if in_range {
        let c = chunks[c_index];
        for (var k = 0u; k < ITEMS; k++) {
            let j = lid + k * WG_SIZE;
            if j < c.count {
                let i = c.start + j;
                let d = heights[i + c.lag] - heights[i];
                s += d * d;
            }
        }
    }
    acc[lid] = s;
    workgroupBarrier();
    for (var stride = WG_SIZE / 2u; stride > 0u; stride = stride / 2u) {
        if lid < stride {
            acc[lid] += acc[lid + stride];
        }
        workgroupBarrier();
    }
    if in_range && lid == 0u {
        partials[c_index] = acc[0];
    }
}
