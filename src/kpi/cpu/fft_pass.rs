//! CPU twin of `shaders/fft_pass.wgsl`: one radix-2 Stockham pass (Ns = 1,
//! 2, 4, …, N/2) over every segment, ping-ponging between two buffers; after
//! log2 N passes the forward DFT X_k = Σ x_n e^{−2πikn/N} is in natural
//! order. Twiddles come from a table computed in f64 (uploaded as f32).
//! (The CPU engine's own PSD uses the realfft crate; this twin is the
//! reference the shader is compared with, and is itself checked against
//! realfft in the tests.)

use crate::kpi::roughness_batch::FFT_N;
use rayon::prelude::*;

/// e^{−2πik/N} for k < N/2.
pub fn twiddles() -> Vec<[f64; 2]> {
    (0..FFT_N / 2)
        .map(|k| {
            let a = -std::f64::consts::TAU * k as f64 / FFT_N as f64;
            [a.cos(), a.sin()]
        })
        .collect()
}

/// One pass with sub-transform size `ns`.
pub fn fft_pass(src: &[[f64; 2]], dst: &mut [[f64; 2]], ns: usize, tw: &[[f64; 2]]) {
    let half = FFT_N / 2;
    dst.par_chunks_mut(FFT_N)
        .zip(src.par_chunks(FFT_N))
        .for_each(|(d, s)| {
            for j in 0..half {
                let (v0, v1) = (s[j], s[j + half]);
                let t = tw[(j % ns) * (half / ns)];
                let v1t = [v1[0] * t[0] - v1[1] * t[1], v1[0] * t[1] + v1[1] * t[0]];
                let idx = (j / ns) * ns * 2 + (j % ns);
                d[idx] = [v0[0] + v1t[0], v0[1] + v1t[1]];
                d[idx + ns] = [v0[0] - v1t[0], v0[1] - v1t[1]];
            }
        });
}

/// All passes: the forward DFT of every segment.
pub(crate) fn fft(mut data: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let tw = twiddles();
    let mut other = vec![[0.0; 2]; data.len()];
    let mut ns = 1;
    while ns < FFT_N {
        fft_pass(&data, &mut other, ns, &tw);
        std::mem::swap(&mut data, &mut other);
        ns *= 2;
    }
    data
}
