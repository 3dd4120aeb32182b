//! Tread-depth readings (CSV): per run and wheel, the depth measured at
//! several spots across the tread width (not equally spaced), several
//! readings per spot, with the new-tire depth. One row per reading.

use super::{IngestError, Result, positive};
use crate::Wheel;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One reading of one spot (a row of the CSV).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WearReading {
    pub run: String,
    pub wheel: Wheel,
    pub tire_set: String,
    /// Spot number across the width, from the tire's inner (car-side) edge.
    pub spot: u32,
    /// Spot position from the inner tread edge (mm).
    pub position_mm: f64,
    /// Tread width (mm), the same for every row of a tire.
    pub tread_width_mm: f64,
    /// Reading number at this spot (1, 2, ...).
    pub reading: u32,
    /// Measured remaining tread depth (mm).
    pub depth_mm: f64,
    /// Tread depth of the new tire (mm).
    pub new_depth_mm: f64,
}

/// Largest wear-reading CSV read (bytes): about ten million readings.
const MAX_WEAR_CSV_BYTES: u64 = 1 << 30;
/// Largest accepted new-tire tread depth (mm); race tires have 2-8 mm.
pub(crate) const MAX_NEW_DEPTH_MM: f64 = 100.0;
/// Largest accepted tread width (mm).
pub(crate) const MAX_TREAD_WIDTH_MM: f64 = 2000.0;

/// Reads and checks a wear-reading CSV. Errors name the file and the line.
pub fn read_wear_csv(path: &Path) -> Result<Vec<WearReading>> {
    let csv_err = |source| IngestError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let mut rdr = csv::Reader::from_reader(super::open_bounded(path, MAX_WEAR_CSV_BYTES)?);
    let mut out = Vec::new();
    for (i, row) in rdr.deserialize::<WearReading>().enumerate() {
        let r = row.map_err(csv_err)?;
        let rec = format!(
            "line {} (run {}, wheel {}, spot {})",
            i + 2,
            r.run,
            r.wheel,
            r.spot
        );
        let bad = |what: String| IngestError::invalid(path, rec.clone(), what);
        if !(positive(r.new_depth_mm) && r.new_depth_mm <= MAX_NEW_DEPTH_MM) {
            return Err(bad(format!(
                "new_depth_mm must be in (0, {MAX_NEW_DEPTH_MM}] mm, got {:?}",
                r.new_depth_mm
            )));
        }
        if r.spot == 0 || r.reading == 0 {
            return Err(bad(format!(
                "spot and reading are numbered from 1, got spot {} reading {}",
                r.spot, r.reading
            )));
        }
        if !(positive(r.tread_width_mm) && r.tread_width_mm <= MAX_TREAD_WIDTH_MM) {
            return Err(bad(format!(
                "tread_width_mm must be in (0, {MAX_TREAD_WIDTH_MM}] mm, got {:?}",
                r.tread_width_mm
            )));
        }
        if !r.depth_mm.is_finite() || r.depth_mm < 0.0 || r.depth_mm > 1.5 * r.new_depth_mm {
            return Err(bad(format!(
                "depth_mm = {:?} is outside 0..1.5 x new depth ({:?} mm)",
                r.depth_mm, r.new_depth_mm
            )));
        }
        if !positive(r.tread_width_mm) || !(0.0..=r.tread_width_mm).contains(&r.position_mm) {
            return Err(bad(format!(
                "position_mm = {:?} is outside the tread width 0..{:?} mm",
                r.position_mm, r.tread_width_mm
            )));
        }
        out.push(r);
    }
    Ok(out)
}

/// A disagreement between wear readings and the manifest.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct WearProblem {
    /// The manifest run it costs (None: the readings name no run of the manifest).
    pub run: Option<String>,
    /// What was wrong, naming the file and line.
    pub what: String,
}

/// Checks readings against the manifest: the run exists, the tire set is
/// the one the manifest mounts on that wheel, and one tire has one tread
/// width. The first problem of each run is returned (lines counted from the
/// header as line 1, as [`read_wear_csv`] reads them).
pub(crate) fn check_against_manifest(
    path: &Path,
    readings: &[WearReading],
    manifest: &super::manifest::Manifest,
) -> Vec<WearProblem> {
    use std::collections::{BTreeMap, BTreeSet};
    let runs: BTreeMap<&str, &super::manifest::Run> =
        manifest.runs.iter().map(|r| (r.id.as_str(), r)).collect();
    let mut width: BTreeMap<(&str, Wheel), (f64, usize)> = BTreeMap::new();
    let mut unknown: BTreeMap<&str, usize> = BTreeMap::new();
    let mut reported: BTreeSet<&str> = BTreeSet::new();
    let mut out = Vec::new();
    for (i, r) in readings.iter().enumerate() {
        let line = i + 2;
        let Some(run) = runs.get(r.run.as_str()) else {
            unknown.entry(&r.run).or_insert(line);
            continue;
        };
        let mut problem = None;
        let mounted = run.tire_sets.get(r.wheel);
        if mounted != r.tire_set {
            problem = Some(format!(
                "tire_set '{}' but the manifest mounts '{mounted}' on {}",
                r.tire_set, r.wheel
            ));
        }
        let (w, first) = *width
            .entry((&r.run, r.wheel))
            .or_insert((r.tread_width_mm, line));
        if problem.is_none() && w != r.tread_width_mm {
            problem = Some(format!(
                "tread_width_mm {} differs from {w} on line {first} for the same tire",
                r.tread_width_mm
            ));
        }
        if let Some(what) = problem
            && reported.insert(&run.id)
        {
            out.push(WearProblem {
                run: Some(run.id.clone()),
                what: format!(
                    "{}: line {line} (run {}, wheel {}): {what}",
                    path.display(),
                    r.run,
                    r.wheel
                ),
            });
        }
    }
    for (run, line) in unknown {
        out.push(WearProblem {
            run: None,
            what: format!(
                "{}: line {line}: run '{run}' is not in the manifest; its readings are not used",
                path.display()
            ),
        });
    }
    out
}

/// Writes wear readings as CSV, atomically.
pub fn write_wear_csv(path: &Path, rows: &[WearReading]) -> Result<()> {
    crate::atomic::write_csv(path, rows).map_err(|e| IngestError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_hand_written_file_and_names_bad_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("wear.csv");
        std::fs::write(
            &p,
            "run,wheel,tire_set,spot,position_mm,tread_width_mm,reading,depth_mm,new_depth_mm\n\
             R1,FL,T1,1,15,300,1,3.1,4.0\n\
             R1,FL,T1,1,15,300,2,3.2,4.0\n\
             R1,FL,T1,2,80,300,1,7.5,4.0\n",
        )
        .unwrap();
        let err = read_wear_csv(&p).unwrap_err().to_string();
        assert!(
            err.contains("wear.csv") && err.contains("line 4") && err.contains("spot 2"),
            "{err}"
        );
        std::fs::write(
            &p,
            "run,wheel,tire_set,spot,position_mm,tread_width_mm,reading,depth_mm,new_depth_mm\n\
             R1,RR,T1,1,15,300,1,3.1,4.0\n",
        )
        .unwrap();
        let rows = read_wear_csv(&p).unwrap();
        assert_eq!(rows[0].wheel, Wheel::RR);
        assert_eq!(rows[0].depth_mm, 3.1);
    }
}
