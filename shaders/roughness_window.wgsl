// Welch segments of road profiles: each segment of N heights, its mean
// removed, times the periodic Hann window scaled to mean(w²) = 1, as complex
// numbers for fft_pass. One workgroup per segment. CPU twin:
// src/kpi/cpu/roughness_window.rs.

// Must match src/kpi/roughness_batch.rs (FFT_N, Segment) and HANN_RMS (checked by tests/shader_contract.rs).
const N: u32 = 4096u;
const WG_SIZE: u32 = 256u;
const ITEMS: u32 = 16u; // N / WG_SIZE
const HANN_RMS: f32 = 0.6123724356957945;
const TAU: f32 = 6.283185307179586;

struct Segment {
    start: u32,
    profile: u32,
}

@group(0) @binding(0) var<storage, read> heights: array<f32>;
@group(0) @binding(1) var<storage, read> segments: array<Segment>;
@group(0) @binding(2) var<storage, read_write> out: array<vec2<f32>>;

var<workgroup> acc: array<f32, WG_SIZE>;

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let s_index = wg.x + wg.y * nwg.x;
    let in_range = s_index < arrayLength(&segments);
    var start = 0u;
    if in_range {
        start = segments[s_index].start;
    }
    var s = 0.0;
    if in_range {
        for (var k = 0u; k < ITEMS; k++) {
            s += heights[start + lid + k * WG_SIZE];
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
    let mean = acc[0] / f32(N);
    if in_range {
        for (var k = 0u; k < ITEMS; k++) {
            let i = lid + k * WG_SIZE;
            let w = 0.5 - 0.5 * cos(TAU * f32(i) / f32(N));
            out[s_index * N + i] = vec2<f32>((heights[start + i] - mean) * w / HANN_RMS, 0.0);
        }
    }
}
