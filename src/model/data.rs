//! From the KPI database to model data: which columns may be inputs, the
//! split into training and testing data by whole events (never by rows),
//! and the correlation-based input selection of the paper (sections 4.1, 4.2).

use crate::kpi::KpiRow;
use std::collections::BTreeSet;

/// The target column.
pub(crate) const TARGET: &str = "wear_mean_pct";

/// Numeric KPI columns that may be model inputs: the paper's tables 3, 4
/// and 5 (the HDC Hurst cross-check and the data-quality columns are not).
pub(crate) fn candidate_inputs() -> Vec<&'static str> {
    KpiRow::NUMBER_COLUMNS
        .iter()
        .copied()
        .filter(|c| {
            !matches!(
                *c,
                TARGET
                    | "hurst_hdc"
                    | "telemetry_duration_s"
                    | "dropout_time_s"
                    | "invalid_samples"
                    | "worn_through_readings"
            )
        })
        .collect()
}

/// Indices of training and testing rows. The testing data are whole events:
/// those listed, or by default every third event in event-id order (the
/// 3rd, 6th, ...), about a third of the events, as the paper kept a separate
/// database of events (80 against 200 observations).
pub(crate) fn split_by_events(
    rows: &[KpiRow],
    test_events: Option<&[String]>,
) -> (Vec<usize>, Vec<usize>, Vec<String>) {
    let events: BTreeSet<&str> = rows.iter().map(|r| r.event.as_str()).collect();
    let test: Vec<String> = match test_events {
        Some(list) => list.to_vec(),
        None => events
            .iter()
            .enumerate()
            .filter(|(i, _)| i % 3 == 2)
            .map(|(_, e)| e.to_string())
            .collect(),
    };
    let (mut tr, mut te) = (Vec::new(), Vec::new());
    for (i, r) in rows.iter().enumerate() {
        if test.contains(&r.event) {
            te.push(i)
        } else {
            tr.push(i)
        }
    }
    (tr, te, test)
}

/// Pearson correlation.
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

/// Greedy selection of mutually uncorrelated inputs. Candidates are taken in
/// the given order (for the network: by |correlation with the target|,
/// strongest first, after dropping those at or below `min_target_corr`); a
/// candidate is kept if its |correlation| with every input already kept is
/// at most `max_mutual_corr`. Constant candidates are dropped.
pub(crate) fn select_inputs(
    columns: &[(&str, Vec<f64>)],
    target: Option<(&[f64], f64)>,
    max_mutual_corr: f64,
) -> Vec<String> {
    let mut order: Vec<(usize, f64)> = columns
        .iter()
        .enumerate()
        .filter(|(_, (_, v))| v.iter().any(|x| *x != v[0]))
        .map(|(i, (_, v))| (i, target.map_or(0.0, |(y, _)| correlation(v, y).abs())))
        .collect();
    if let Some((_, min)) = target {
        order.retain(|(_, c)| *c > min);
        order.sort_by(|a, b| b.1.total_cmp(&a.1));
    }
    let mut kept: Vec<usize> = Vec::new();
    for (i, _) in order {
        if kept
            .iter()
            .all(|&k| correlation(&columns[i].1, &columns[k].1).abs() <= max_mutual_corr)
        {
            kept.push(i);
        }
    }
    kept.iter().map(|&i| columns[i].0.to_string()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_keeps_events_whole() {
        let rows: Vec<KpiRow> = ["E1", "E2", "E3", "E1", "E4", "E5", "E6"]
            .iter()
            .map(|e| KpiRow {
                event: e.to_string(),
                ..Default::default()
            })
            .collect();
        let (tr, te, events) = split_by_events(&rows, None);
        assert_eq!(events, ["E3", "E6"]);
        assert_eq!(te, [2, 6]);
        assert_eq!(tr.len(), 5);
        let (_, te, _) = split_by_events(&rows, Some(&["E1".to_string()]));
        assert_eq!(te, [0, 3]);
        assert!(!candidate_inputs().contains(&TARGET));
        assert_eq!(candidate_inputs().len(), KpiRow::NUMBER_COLUMNS.len() - 6);
    }

    #[test]
    fn selection_by_hand() {
        // y = a; b = 2a (duplicate of a); c uncorrelated with a; d weakly related to y.
        let a = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let b: Vec<f64> = a.iter().map(|x| 2.0 * x).collect();
        let c = vec![1.0, -1.0, 1.0, -1.0, 1.0, -1.0];
        let k = vec![3.0; 6];
        let cols = [("a", a.clone()), ("b", b), ("c", c.clone()), ("k", k)];
        // Without the target: a kept, b dropped (|r| = 1), c kept (|r(a, c)| = 0.29), constant k dropped.
        assert_eq!(select_inputs(&cols, None, 0.9), ["a", "c"]);
        // With the target y = a and a 0.15 floor: c's |r| with y is 0.29 > 0.15, kept after a.
        assert_eq!(select_inputs(&cols, Some((&a, 0.15)), 0.9), ["a", "c"]);
        assert!((correlation(&a, &c) + 0.2927700218845599).abs() < 1e-12);
        // A floor above 0.29 drops c.
        assert_eq!(select_inputs(&cols, Some((&a, 0.3)), 0.9), ["a"]);
    }
}
