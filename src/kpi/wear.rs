//! Mean tread wear (the paper's Wear_Mean, section 3.4): readings averaged
//! per spot, interpolated across the width to equally spaced virtual ribs,
//! wear of each rib in % of the new depth, averaged over the ribs.

use crate::Wheel;
use crate::ingest::wear::WearReading;
use std::collections::BTreeMap;

/// Number of equally spaced virtual ribs across the tread.
pub(crate) const VIRTUAL_RIBS: usize = 10;

/// Mean wear (% of new depth) of every (run, wheel) in the readings.
/// Between spots depth is linear in position; beyond the outermost spots
/// the nearest spot's depth holds.
pub(crate) fn mean_wear(readings: &[WearReading]) -> BTreeMap<(String, Wheel), f64> {
    let mut tires: BTreeMap<(String, Wheel), Vec<&WearReading>> = BTreeMap::new();
    for r in readings {
        tires.entry((r.run.clone(), r.wheel)).or_default().push(r);
    }
    tires
        .into_iter()
        .map(|(key, rows)| {
            // Average the readings of each spot.
            let mut spots: BTreeMap<u32, (f64, f64, usize)> = BTreeMap::new();
            for r in &rows {
                let e = spots.entry(r.spot).or_insert((r.position_mm, 0.0, 0));
                e.1 += r.depth_mm;
                e.2 += 1;
            }
            let mut pts: Vec<(f64, f64)> =
                spots.values().map(|&(x, s, n)| (x, s / n as f64)).collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let width = rows[0].tread_width_mm;
            let new = rows.iter().map(|r| r.new_depth_mm).sum::<f64>() / rows.len() as f64;
            let depth_at = |x: f64| {
                if x <= pts[0].0 {
                    return pts[0].1;
                }
                if x >= pts[pts.len() - 1].0 {
                    return pts[pts.len() - 1].1;
                }
                let i = pts.partition_point(|p| p.0 <= x) - 1;
                let w = (x - pts[i].0) / (pts[i + 1].0 - pts[i].0);
                pts[i].1 * (1.0 - w) + pts[i + 1].1 * w
            };
            let wear = (0..VIRTUAL_RIBS)
                .map(|j| {
                    let x = (j as f64 + 0.5) * width / VIRTUAL_RIBS as f64;
                    100.0 * (new - depth_at(x)) / new
                })
                .sum::<f64>()
                / VIRTUAL_RIBS as f64;
            (key, wear)
        })
        .collect()
}

/// Depth, as a fraction of the new depth, at or below which a reading counts
/// as worn through. A gauge on a tread that is gone reads the last fraction of
/// a millimetre of rubber or the belt, not zero: 5 % of a 4 mm tread is
/// 0.2 mm, five gauge standard deviations (0.04 mm) above 0.
pub const WORN_THROUGH_FRACTION: f64 = 0.05;

/// Readings at or below [`WORN_THROUGH_FRACTION`] of the new depth per (run,
/// wheel): the tread worn through at that spot, so the tire's mean wear is
/// only a lower bound (censored).
pub fn worn_through_readings(readings: &[WearReading]) -> BTreeMap<(String, Wheel), f64> {
    let mut out: BTreeMap<(String, Wheel), f64> = BTreeMap::new();
    for r in readings {
        let worn = r.depth_mm <= WORN_THROUGH_FRACTION * r.new_depth_mm;
        *out.entry((r.run.clone(), r.wheel)).or_default() += worn as u8 as f64;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_ribs_by_hand() {
        // Spots at 20 mm (depth 3.0) and 80 mm (depth 2.0) on a 100 mm tread, new 4.0 mm.
        // Rib centres 5, 15, ..., 95: depths 3,3,2.9167,2.75,2.5833,2.4167,2.25,2.0833,2,2
        // -> mean depth 2.5 mm -> wear 37.5 %.
        let row = |spot, pos, reading, depth| WearReading {
            run: "R".into(),
            wheel: Wheel::FL,
            tire_set: "T".into(),
            spot,
            position_mm: pos,
            tread_width_mm: 100.0,
            reading,
            depth_mm: depth,
            new_depth_mm: 4.0,
        };
        let rows = vec![
            row(1, 20.0, 1, 2.9),
            row(1, 20.0, 2, 3.1),
            row(2, 80.0, 1, 2.0),
        ];
        let w = mean_wear(&rows);
        assert!((w[&("R".to_string(), Wheel::FL)] - 37.5).abs() < 1e-9);
        // Readings at 0 and at 0.2 mm (5 % of 4 mm) are worn through, 0.21 mm is not.
        let mut worn = rows.clone();
        worn.push(row(2, 80.0, 2, 0.0));
        worn.push(row(2, 80.0, 3, 0.21));
        worn[0].depth_mm = 0.2;
        assert_eq!(
            worn_through_readings(&worn)[&("R".to_string(), Wheel::FL)],
            2.0
        );
        assert_eq!(
            worn_through_readings(&rows)[&("R".to_string(), Wheel::FL)],
            0.0
        );
    }
}
