//! Friction-energy maps: the friction energy of one tire and run binned over
//! (surface temperature × inner-liner temperature) and over (sliding speed ×
//! surface temperature), and its lateral part over (surface × inner-liner
//! temperature), on fixed bin edges, so that threshold effects can be
//! tested later without re-reading telemetry. Values outside the edges go
//! to the first or last bin.

/// Surface-temperature bins: 20..140 °C, 5 K wide.
pub const T_SURFACE_BINS: Bins = Bins {
    lo: 20.0,
    width: 5.0,
    n: 24,
};
/// Inner-liner temperature bins: 40..160 °C, 5 K wide.
pub const T_INNER_BINS: Bins = Bins {
    lo: 40.0,
    width: 5.0,
    n: 24,
};
/// Sliding-speed bins: 0..10 m/s, 0.5 m/s wide.
pub const SLIDING_SPEED_BINS: Bins = Bins {
    lo: 0.0,
    width: 0.5,
    n: 20,
};

/// Equal-width bins `[lo + i·width, lo + (i+1)·width)`, clamped at both ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bins {
    pub lo: f64,
    pub width: f64,
    pub n: usize,
}

impl Bins {
    pub fn index(&self, x: f64) -> usize {
        let i = (x - self.lo) / self.width;
        // For i ≥ 0 truncation is floor (without SSE4.1 floor is a libcall);
        // below 0 and NaN go to bin 0.
        // min(⌊i⌋, n − 1) = ⌊min(i, n − 1)⌋ for i ≥ 0.
        if i >= 0.0 {
            let i = i.min((self.n - 1) as f64);
            // SAFETY: 0 ≤ i ≤ n − 1 (finite, a bin count) fits a u32.
            unsafe { i.to_int_unchecked::<u32>() as usize }
        } else {
            0
        }
    }
    pub(crate) fn lower_edge(&self, i: usize) -> f64 {
        self.lo + self.width * i as f64
    }
    /// Mid-point of bin i: the value a bin stands for in sums over the map.
    pub fn mid(&self, i: usize) -> f64 {
        self.lower_edge(i) + 0.5 * self.width
    }
}

/// The maps of one tire and run (J per bin, row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct EnergyMaps {
    /// [T_surface bin][T_inner bin].
    pub surface_inner: Vec<f64>,
    /// [sliding-speed bin][T_surface bin].
    pub speed_surface: Vec<f64>,
    /// Lateral friction energy −F_y·v_sy·Δt, [T_surface bin][T_inner bin]
    /// (all zero in files written before it existed).
    pub lateral_surface_inner: Vec<f64>,
    /// The tire's condition energy maps, where its extraction wrote them
    /// (`NAME.condition_maps.parquet`; attached by [`read_tire_maps`]).
    pub conditions: Option<Box<crate::kpi::cpu::condition_map::ConditionMaps>>,
}

impl Default for EnergyMaps {
    fn default() -> Self {
        Self::new()
    }
}

impl EnergyMaps {
    pub fn new() -> Self {
        EnergyMaps {
            surface_inner: vec![0.0; T_SURFACE_BINS.n * T_INNER_BINS.n],
            speed_surface: vec![0.0; SLIDING_SPEED_BINS.n * T_SURFACE_BINS.n],
            lateral_surface_inner: vec![0.0; T_SURFACE_BINS.n * T_INNER_BINS.n],
            conditions: None,
        }
    }

    /// Adds lateral friction energy to the lateral map (the total maps take
    /// it through [`EnergyMaps::add`]).
    #[cfg(test)]
    pub(crate) fn add_lateral(&mut self, t_surface: f64, t_inner: f64, lateral_j: f64) {
        let s = T_SURFACE_BINS.index(t_surface);
        self.lateral_surface_inner[s * T_INNER_BINS.n + T_INNER_BINS.index(t_inner)] += lateral_j;
    }

    /// Whether the lateral map was filled (files from before it are not).
    pub(crate) fn has_lateral(&self) -> bool {
        self.lateral_surface_inner.iter().any(|e| *e != 0.0)
    }

    #[cfg(test)]
    pub(crate) fn add(&mut self, t_surface: f64, t_inner: f64, sliding_speed: f64, energy_j: f64) {
        let s = T_SURFACE_BINS.index(t_surface);
        self.surface_inner[s * T_INNER_BINS.n + T_INNER_BINS.index(t_inner)] += energy_j;
        self.speed_surface[SLIDING_SPEED_BINS.index(sliding_speed) * T_SURFACE_BINS.n + s] +=
            energy_j;
    }

    pub fn total(&self) -> f64 {
        self.surface_inner.iter().sum()
    }

    /// Σ E·f(T_surface, T_inner) over the non-empty bins of the
    /// surface × inner-liner map, at the bin mid-points (J).
    pub(crate) fn weighted_surface_inner(&self, f: impl FnMut(f64, f64) -> f64) -> f64 {
        weighted(&self.surface_inner, T_SURFACE_BINS, T_INNER_BINS, f)
    }

    /// Σ E_y·f(T_surface, T_inner) over the non-empty bins of the lateral
    /// map, at the bin mid-points (J).
    pub(crate) fn weighted_lateral_surface_inner(&self, f: impl FnMut(f64, f64) -> f64) -> f64 {
        weighted(&self.lateral_surface_inner, T_SURFACE_BINS, T_INNER_BINS, f)
    }

    /// Σ E·f(sliding speed, T_surface) over the non-empty bins of the
    /// sliding-speed × surface map, at the bin mid-points (J).
    pub(crate) fn weighted_speed_surface(&self, f: impl FnMut(f64, f64) -> f64) -> f64 {
        weighted(&self.speed_surface, SLIDING_SPEED_BINS, T_SURFACE_BINS, f)
    }
}

/// Σ E·f(row mid-point, column mid-point) over the non-empty bins of a map.
fn weighted(map: &[f64], rows: Bins, cols: Bins, mut f: impl FnMut(f64, f64) -> f64) -> f64 {
    let mut s = 0.0;
    for i in 0..rows.n {
        for j in 0..cols.n {
            let e = map[i * cols.n + j];
            if e != 0.0 {
                s += e * f(rows.mid(i), cols.mid(j));
            }
        }
    }
    s
}

/// Reads the energy-map side table written by `tirewear extract`
/// (`NAME.energy_maps.parquet`: run, wheel, map, i, j, x_lo, y_lo, energy_j;
/// maps `surface_inner`, `speed_surface`, `lateral_surface_inner`;
/// non-empty bins only) back into maps keyed by (run, wheel). A bin outside
/// the fixed grid, an unknown map name or wheel is an error naming the record.
pub fn read_energy_maps(
    path: &std::path::Path,
) -> Result<std::collections::BTreeMap<super::TireRun, EnergyMaps>, crate::ingest::IngestError> {
    use crate::ingest::IngestError;
    use arrow_array::{Array, Float64Array, StringArray, UInt32Array};
    use arrow_schema::DataType;
    let mut out: std::collections::BTreeMap<super::TireRun, EnergyMaps> = Default::default();
    // The three maps' cells side by side: one bit each per tire.
    let grids = [
        (T_SURFACE_BINS.n, T_INNER_BINS.n),
        (SLIDING_SPEED_BINS.n, T_SURFACE_BINS.n),
        (T_SURFACE_BINS.n, T_INNER_BINS.n),
    ];
    let first_cell: [usize; 3] =
        std::array::from_fn(|m| grids[..m].iter().map(|(a, b)| a * b).sum());
    let mut given = crate::kpi::table::CellsGiven::new(grids.iter().map(|(a, b)| a * b).sum());
    let mut record = 0usize;
    for batch in crate::kpi::table::side_batches(path)? {
        let batch = batch?;
        let col = |name: &str, ty: &DataType| {
            crate::kpi::table::checked_column(path, &batch, name, ty, record)
        };
        let (run, wheel, map) = (
            col("run", &DataType::Utf8)?,
            col("wheel", &DataType::Utf8)?,
            col("map", &DataType::Utf8)?,
        );
        let (i, j, e) = (
            col("i", &DataType::UInt32)?,
            col("j", &DataType::UInt32)?,
            col("energy_j", &DataType::Float64)?,
        );
        let s = |a: &std::sync::Arc<dyn Array>| {
            a.as_any()
                .downcast_ref::<StringArray>()
                .expect("cast")
                .clone()
        };
        let u = |a: &std::sync::Arc<dyn Array>| {
            a.as_any()
                .downcast_ref::<UInt32Array>()
                .expect("cast")
                .clone()
        };
        let (run, wheel, map, i, j) = (s(&run), s(&wheel), s(&map), u(&i), u(&j));
        let e = e
            .as_any()
            .downcast_ref::<Float64Array>()
            .expect("cast")
            .clone();
        for k in 0..batch.num_rows() {
            record += 1;
            let w = super::wheel_cell(path, record, wheel.value(k))?;
            let tire = (run.value(k).to_string(), w);
            let (bi, bj) = (i.value(k) as usize, j.value(k) as usize);
            let slot = match map.value(k) {
                "surface_inner" => 0,
                "speed_surface" => 1,
                "lateral_surface_inner" => 2,
                other => {
                    return Err(IngestError::invalid(
                        path,
                        format!("record {record}"),
                        format!("unknown map '{other}'"),
                    ));
                }
            };
            let (ni, nj) = grids[slot];
            if bi >= ni || bj >= nj {
                return Err(IngestError::invalid(
                    path,
                    format!("record {record}"),
                    format!(
                        "bin ({bi}, {bj}) outside the {ni}×{nj} grid of map '{}'",
                        map.value(k)
                    ),
                ));
            }
            if !given.first(&tire, first_cell[slot] + bi * nj + bj) {
                return Err(IngestError::invalid(
                    path,
                    format!("record {record}"),
                    format!(
                        "bin ({bi}, {bj}) of map '{}' for run {} wheel {w} given twice (a \
                         table holds each bin of a tire once)",
                        map.value(k),
                        tire.0
                    ),
                ));
            }
            if !e.value(k).is_finite() {
                return Err(IngestError::invalid(
                    path,
                    format!("record {record}"),
                    format!("energy_j = {} is not finite", e.value(k)),
                ));
            }
            let m = out.entry(tire).or_default();
            let data = match slot {
                0 => &mut m.surface_inner,
                1 => &mut m.speed_surface,
                _ => &mut m.lateral_surface_inner,
            };
            data[bi * nj + bj] += e.value(k);
        }
    }
    Ok(out)
}

/// Every tire's maps of one extraction: the energy maps beside a KPI table
/// (`NAME.energy_maps.parquet`), with its condition maps attached where
/// `NAME.condition_maps.parquet` exists (older extractions have none). Each
/// side table must come from the same extraction as the KPI table. An
/// absent energy-map table gives no maps.
pub fn read_tire_maps(
    kpis: &std::path::Path,
) -> Result<std::collections::BTreeMap<super::TireRun, EnergyMaps>, crate::ingest::IngestError> {
    use crate::kpi::table::{check_same_extraction, side_table_path};
    let side = |suffix: &str| side_table_path(kpis, suffix);
    let energy = side("energy_maps.parquet");
    if !energy.exists() {
        return Ok(Default::default());
    }
    check_same_extraction(kpis, &energy)?;
    let mut maps = read_energy_maps(&energy)?;
    let conditions = side("condition_maps.parquet");
    if conditions.exists() {
        check_same_extraction(kpis, &conditions)?;
        let mut cm = crate::kpi::cpu::condition_map::read_condition_maps(&conditions)?;
        for (key, m) in maps.iter_mut() {
            m.conditions = Some(Box::new(cm.remove(key).unwrap_or_default()));
        }
    }
    Ok(maps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_clamp_and_split_by_hand() {
        assert_eq!(T_SURFACE_BINS.index(19.0), 0);
        assert_eq!(T_SURFACE_BINS.index(24.999), 0);
        assert_eq!(T_SURFACE_BINS.index(25.0), 1);
        assert_eq!(T_SURFACE_BINS.index(500.0), 23);
        assert_eq!(T_SURFACE_BINS.index(f64::NAN), 0);
        assert_eq!(T_SURFACE_BINS.index(f64::INFINITY), 23);
        assert_eq!(T_SURFACE_BINS.index(f64::NEG_INFINITY), 0);
        let mut m = EnergyMaps::new();
        m.add(72.0, 101.0, 1.2, 10.0);
        m.add(72.0, 131.0, 6.0, 5.0);
        assert_eq!(m.surface_inner[10 * 24 + 12], 10.0);
        assert_eq!(m.surface_inner[10 * 24 + 18], 5.0);
        assert_eq!(m.speed_surface[2 * 24 + 10], 10.0);
        assert_eq!(m.speed_surface[12 * 24 + 10], 5.0);
        assert_eq!(m.total(), 15.0);
    }
}
