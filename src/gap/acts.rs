//! Where a candidate term acts: the step-1 slices whose gap the term
//! follows. The term's change t is what adding it changes in the prediction
//! (baseline + term refitted, minus the baseline refitted: the baseline
//! gives back what the term takes over). For a slice S with mean baseline
//! residual r̄_S and mean change t̄_S (both % of tread), the term
//! accounts for t̄_S / r̄_S of the slice's offset; slices are ranked by the
//! part of the squared gap that this removes, n_S·t̄_S·r̄_S / Σr²
//! (positive only when the term pushes the way the gap lies).

/// A slice where a term acts.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ActsIn {
    pub slice: String,
    /// t̄_S / r̄_S: the part of the slice's mean residual the term accounts for.
    pub share_of_offset: f64,
    /// n_S·t̄_S·r̄_S / Σr².
    pub share_of_squared_gap: f64,
}

/// The `top` slices (names with their members) where the term's change of
/// the prediction `term` (per row) follows the residual `r` most.
pub(crate) fn acts_in(
    term: &[f64],
    r: &[f64],
    slices: &[(&str, Vec<bool>)],
    top: usize,
) -> Vec<ActsIn> {
    let total_sq: f64 = r.iter().map(|v| v * v).sum();
    let mut out: Vec<ActsIn> = slices
        .iter()
        .filter_map(|(name, members)| {
            let (mut n, mut st, mut sr) = (0usize, 0.0, 0.0);
            for ((m, t), v) in members.iter().zip(term).zip(r) {
                if *m {
                    n += 1;
                    st += t;
                    sr += v;
                }
            }
            if n == 0 || sr == 0.0 || total_sq <= 0.0 {
                return None;
            }
            let (tm, rm) = (st / n as f64, sr / n as f64);
            let removed = n as f64 * tm * rm / total_sq;
            (removed > 0.0).then(|| ActsIn {
                slice: name.to_string(),
                share_of_offset: tm / rm,
                share_of_squared_gap: removed,
            })
        })
        .collect();
    out.sort_by(|a, b| b.share_of_squared_gap.total_cmp(&a.share_of_squared_gap));
    out.truncate(top);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_the_slices_whose_gap_the_term_follows() {
        // Residual +2 on rows 0..4, −1 elsewhere (Σr² = 4·4 + 4·1 = 20); the
        // term adds 1 on rows 0..4 only.
        let r = [2.0, 2.0, 2.0, 2.0, -1.0, -1.0, -1.0, -1.0];
        let term = [1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
        let hot = (0..8).map(|i| i < 4).collect::<Vec<_>>();
        let cold = hot.iter().map(|h| !h).collect::<Vec<_>>();
        let half = (0..8).map(|i| i % 2 == 0).collect::<Vec<_>>();
        let a = acts_in(
            &term,
            &r,
            &[("cold", cold), ("half", half), ("hot", hot)],
            5,
        );
        // hot: t̄ = 1, r̄ = 2 → half the offset, 4·1·2/20 = 0.4 of the squared gap;
        // half: t̄ = 0.5, r̄ = 0.5 → all of it, 4·0.25/20 = 0.05; cold: t̄ = 0 → not listed.
        assert_eq!(a.len(), 2);
        assert_eq!(a[0].slice, "hot");
        assert!((a[0].share_of_offset - 0.5).abs() < 1e-12);
        assert!((a[0].share_of_squared_gap - 0.4).abs() < 1e-12);
        assert_eq!(a[1].slice, "half");
        assert!((a[1].share_of_offset - 1.0).abs() < 1e-12);
        assert!((a[1].share_of_squared_gap - 0.05).abs() < 1e-12);
    }
}
