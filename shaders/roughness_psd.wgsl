// Welch PSD of road profiles in the SurfaceTopography convention: per profile
// and frequency k ≤ N/2, C_k = Δx²/L · mean over segments of |X_k|²
// (L = N·Δx). One thread per (profile, k). CPU twin: src/kpi/cpu/roughness_psd.rs.

// Must match src/kpi/roughness_batch.rs (FFT_N, PsdProfile) (checked by tests/shader_contract.rs).
const N: u32 = 4096u;
const BINS: u32 = 2049u; // N / 2 + 1
const WG_SIZE: u32 = 256u;

struct PsdProfile {
    seg_first: u32,
    seg_count: u32,
    dx_mm: f32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> spectra: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> profiles: array<PsdProfile>;
@group(0) @binding(2) var<storage, read_write> psd: array<f32>;

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let t = gid.x + gid.y * nwg.x * WG_SIZE;
    if t >= arrayLength(&profiles) * BINS {
        return;
    }
    let p = profiles[t / BINS];
    let k = t % BINS;
    var acc = 0.0;
    for (var s = p.seg_first; s < p.seg_first + p.seg_count; s++) {
        let x = spectra[s * N + k];
        acc += x.x * x.x + x.y * x.y;
    }
    psd[t] = acc * (p.dx_mm / f32(N)) / f32(p.seg_count);
}
