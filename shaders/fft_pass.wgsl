// One radix-2 Stockham pass of a batched complex FFT of length N: one thread
// per butterfly; after the passes Ns = 1, 2, …, N/2 (ping-ponging between
// two buffers) the forward DFT is in natural order. Longer than a
// workgroup's memory, so each pass is a dispatch over global memory.
// CPU twin: src/kpi/cpu/fft_pass.rs.

// Must match src/kpi/roughness_batch.rs (FFT_N) (checked by tests/shader_contract.rs).
const N: u32 = 4096u;
const WG_SIZE: u32 = 256u;

struct Pass {
    ns: u32,
    butterflies: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> pass_: Pass;
@group(0) @binding(1) var<storage, read> src: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> dst: array<vec2<f32>>;
// e^{−2πik/N} for k < N/2, computed in f64 on the CPU.
@group(0) @binding(3) var<storage, read> twiddles: array<vec2<f32>>;

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let t = gid.x + gid.y * nwg.x * WG_SIZE;
    if t >= pass_.butterflies {
        return;
    }
    let half = N / 2u;
    let base = (t / half) * N;
    let j = t % half;
    let ns = pass_.ns;
    let v0 = src[base + j];
    let v1 = src[base + j + half];
    let w = twiddles[(j % ns) * (half / ns)];
    let v1t = vec2<f32>(v1.x * w.x - v1.y * w.y, v1.x * w.y + v1.y * w.x);
    let idx = (j / ns) * ns * 2u + (j % ns);
    dst[base + idx] = v0 + v1t;
    dst[base + idx + ns] = v0 - v1t;
}
