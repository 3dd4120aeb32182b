//! Road texture profiles: 1-D height profiles z(x), x and z in mm, sampled on
//! an equally spaced grid. One profile per CSV file (`x_mm,z_mm`), or many in
//! one long-format Parquet file (`track, location, x_mm, z_mm`).

use super::{IngestError, Result, positive};
use arrow_array::{Array, Float64Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema};
use std::path::Path;
use std::sync::Arc;

/// Relative tolerance on the spacing of x: profiles must be equally spaced.
const SPACING_RTOL: f64 = 1e-6;

/// Accepted sample spacing Δx (mm): 0.1 µm (a lab profilometer) to 5 mm.
/// Checked before anything is sized from it (the macro/micro filter's
/// kernel has about 0.4 mm / Δx taps).
pub(crate) const DX_RANGE_MM: (f64, f64) = (1e-4, 5.0);
/// Accepted profile length (mm): from 4× the macro/micro cut-off (0.5 mm), so
/// that the split means something, to 100 m.
pub(crate) const LENGTH_RANGE_MM: (f64, f64) = (2.0, 1e5);
/// Most samples in one profile (256 MiB of heights).
pub(crate) const MAX_PROFILE_SAMPLES: usize = 1 << 25;
/// Largest accepted |z| (mm): road texture is millimetres; 1 m is a unit error.
pub(crate) const MAX_ABS_Z_MM: f64 = 1000.0;

/// One measured profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    pub track: String,
    pub location: String,
    /// x of the first sample (mm).
    pub x0_mm: f64,
    /// Sample spacing Δx (mm).
    pub dx_mm: f64,
    /// Heights (mm).
    pub z_mm: Vec<f64>,
}

impl Profile {
    /// Builds a profile from sample columns, checking that x is equally spaced.
    pub(crate) fn from_columns(
        track: &str,
        location: &str,
        x: &[f64],
        z: Vec<f64>,
        path: &Path,
    ) -> Result<Profile> {
        let rec = format!("profile {track}/{location}");
        let bad = |what: String| Err(IngestError::invalid(path, rec.clone(), what));
        if x.len() < 16 {
            return bad(format!("has {} samples, at least 16 are needed", x.len()));
        }
        if x.len() > MAX_PROFILE_SAMPLES {
            return bad(format!(
                "has {} samples, at most {MAX_PROFILE_SAMPLES} are read",
                x.len()
            ));
        }
        let dx = (x[x.len() - 1] - x[0]) / (x.len() - 1) as f64;
        if !positive(dx) {
            return bad("x_mm must increase".into());
        }
        if !(DX_RANGE_MM.0..=DX_RANGE_MM.1).contains(&dx) {
            return bad(format!(
                "sample spacing {dx:e} mm is outside {:e}..{} mm (is x in mm?)",
                DX_RANGE_MM.0, DX_RANGE_MM.1
            ));
        }
        let len = dx * x.len() as f64;
        if !(LENGTH_RANGE_MM.0..=LENGTH_RANGE_MM.1).contains(&len) {
            return bad(format!(
                "length {len} mm is outside {}..{} mm (is x in mm?)",
                LENGTH_RANGE_MM.0, LENGTH_RANGE_MM.1
            ));
        }
        for i in 0..x.len() {
            let expect = x[0] + dx * i as f64;
            if !x[i].is_finite() || (x[i] - expect).abs() > SPACING_RTOL * dx * x.len() as f64 {
                return Err(IngestError::invalid(
                    path,
                    format!("{rec} sample {i}"),
                    format!(
                        "x_mm = {} breaks the equal spacing of {dx} mm (expected {expect})",
                        x[i]
                    ),
                ));
            }
            if !(z[i].is_finite() && z[i].abs() <= MAX_ABS_Z_MM) {
                return Err(IngestError::invalid(
                    path,
                    format!("{rec} sample {i}"),
                    format!(
                        "z_mm = {:?} is not a height within ±{MAX_ABS_Z_MM} mm",
                        z[i]
                    ),
                ));
            }
        }
        if z.iter().all(|&v| v == z[0]) {
            return bad(format!(
                "every z_mm is {}: a flat profile has no texture to measure",
                z[0]
            ));
        }
        Ok(Profile {
            track: track.into(),
            location: location.into(),
            x0_mm: x[0],
            dx_mm: dx,
            z_mm: z,
        })
    }
}

#[derive(serde::Deserialize, serde::Serialize)]
struct CsvRow {
    x_mm: f64,
    z_mm: f64,
}

/// Largest profile CSV read (bytes).
const MAX_CSV_BYTES: u64 = 2 << 30;

/// Reads one profile from a CSV file with header `x_mm,z_mm`.
pub fn read_profile_csv(path: &Path, track: &str, location: &str) -> Result<Profile> {
    let csv_err = |source| IngestError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let file = super::open_bounded(path, MAX_CSV_BYTES)?;
    let mut rdr = csv::Reader::from_reader(file);
    let (mut x, mut z) = (Vec::new(), Vec::new());
    for (i, row) in rdr.deserialize::<CsvRow>().enumerate() {
        let row = row.map_err(csv_err)?;
        if i >= MAX_PROFILE_SAMPLES {
            return Err(IngestError::invalid(
                path,
                format!("line {}", i + 2),
                format!("more than {MAX_PROFILE_SAMPLES} samples"),
            ));
        }
        x.push(row.x_mm);
        z.push(row.z_mm);
    }
    Profile::from_columns(track, location, &x, z, path)
}

/// Writes one profile as CSV, atomically.
pub(crate) fn write_profile_csv(path: &Path, p: &Profile) -> Result<()> {
    crate::atomic::write_with(path, |w| {
        let mut c = csv::Writer::from_writer(w);
        for (i, &z) in p.z_mm.iter().enumerate() {
            c.serialize(CsvRow {
                x_mm: p.x0_mm + p.dx_mm * i as f64,
                z_mm: z,
            })?;
        }
        c.flush()
    })
    .map_err(|e| IngestError::io(path, e))
}

fn bulk_schema() -> Arc<Schema> {
    Arc::new(Schema::new(vec![
        Field::new("track", DataType::Utf8, false),
        Field::new("location", DataType::Utf8, false),
        Field::new("x_mm", DataType::Float64, false),
        Field::new("z_mm", DataType::Float64, false),
    ]))
}

/// Writes many profiles into one long-format Parquet file (one row per
/// sample, zstd-compressed), atomically.
pub fn write_profiles_parquet(path: &Path, profiles: &[Profile]) -> Result<()> {
    let pq = |source| IngestError::Parquet {
        path: path.to_path_buf(),
        source,
    };
    let mut out = crate::atomic::AtomicFile::create(path).map_err(|e| IngestError::io(path, e))?;
    let props = parquet::file::properties::WriterProperties::builder()
        .set_compression(parquet::basic::Compression::ZSTD(Default::default()))
        .build();
    let schema = bulk_schema();
    let sink = super::checksum::CrcWriter::new(out.file());
    let mut w =
        parquet::arrow::ArrowWriter::try_new(sink, schema.clone(), Some(props)).map_err(pq)?;
    for p in profiles {
        let n = p.z_mm.len();
        let batch = RecordBatch::try_new(
            schema.clone(),
            vec![
                Arc::new(StringArray::from(vec![p.track.as_str(); n])),
                Arc::new(StringArray::from(vec![p.location.as_str(); n])),
                Arc::new(Float64Array::from_iter_values(
                    (0..n).map(|i| p.x0_mm + p.dx_mm * i as f64),
                )),
                Arc::new(Float64Array::from(p.z_mm.clone())),
            ],
        )
        .map_err(|e| pq(e.into()))?;
        w.write(&batch).map_err(pq)?;
    }
    super::checksum::seal_arrow(&mut w).map_err(pq)?;
    w.close().map_err(pq)?;
    out.commit().map_err(|e| IngestError::io(path, e))
}

/// Reads every profile of a long-format Parquet file. Rows of one profile
/// must be contiguous and in increasing x. The first profile that fails its
/// checks is the error.
pub fn read_profiles_parquet(path: &Path) -> Result<Vec<Profile>> {
    read_profiles_parquet_each(path)?
        .into_iter()
        .map(|p| p.map_err(|(_, e)| e))
        .collect()
}

/// A profile, or its track and why it failed its checks.
pub(crate) type ProfileResult = std::result::Result<Profile, (String, IngestError)>;

/// Like [`read_profiles_parquet`], but a profile that fails its checks is
/// returned as an error of its own (with its track) and the others are kept;
/// the whole call fails only when the file cannot be read as a profile table.
pub(crate) fn read_profiles_parquet_each(path: &Path) -> Result<Vec<ProfileResult>> {
    let pq = |source| IngestError::Parquet {
        path: path.to_path_buf(),
        source,
    };
    let reader = super::checksum::open_parquet(path)?.batches().map_err(pq)?;
    struct Acc {
        key: (String, String),
        x: Vec<f64>,
        z: Vec<f64>,
    }
    let mut done: Vec<ProfileResult> = Vec::new();
    let mut cur: Option<Acc> = None;
    let mut seen = std::collections::HashSet::new();
    let finish = |acc: Acc, done: &mut Vec<ProfileResult>| -> Result<()> {
        let track = acc.key.0.clone();
        done.push(
            Profile::from_columns(&acc.key.0, &acc.key.1, &acc.x, acc.z, path)
                .map_err(|e| (track, e)),
        );
        Ok(())
    };
    for batch in reader {
        let batch = batch.map_err(|e| pq(e.into()))?;
        let col = |name: &str| {
            batch.column_by_name(name).ok_or_else(|| {
                IngestError::invalid(path, "schema", format!("missing column '{name}'"))
            })
        };
        let (track, loc, x, z) = (col("track")?, col("location")?, col("x_mm")?, col("z_mm")?);
        // Accept what common writers produce (large or dictionary strings, float32) by casting.
        let cast = |a: &Arc<dyn Array>, name: &str, to: &DataType| {
            arrow_cast::cast(a, to).map_err(|e| {
                IngestError::invalid(
                    path,
                    "schema",
                    format!(
                        "column '{name}' ({}) cannot be read as {to}: {e}",
                        a.data_type()
                    ),
                )
            })
        };
        let (track, loc, x, z) = (
            cast(track, "track", &DataType::Utf8)?,
            cast(loc, "location", &DataType::Utf8)?,
            cast(x, "x_mm", &DataType::Float64)?,
            cast(z, "z_mm", &DataType::Float64)?,
        );
        let strings = |a: &Arc<dyn Array>| {
            a.as_any()
                .downcast_ref::<StringArray>()
                .expect("cast to Utf8")
                .clone()
        };
        let floats = |a: &Arc<dyn Array>| {
            a.as_any()
                .downcast_ref::<Float64Array>()
                .expect("cast to Float64")
                .clone()
        };
        let (track, loc, x, z) = (strings(&track), strings(&loc), floats(&x), floats(&z));
        if track.null_count() + loc.null_count() + x.null_count() + z.null_count() > 0 {
            return Err(IngestError::invalid(
                path,
                "columns",
                "null values are not allowed",
            ));
        }
        for i in 0..batch.num_rows() {
            let (t, l) = (track.value(i), loc.value(i));
            let same = matches!(&cur, Some(a) if a.key.0 == t && a.key.1 == l);
            if !same {
                if let Some(acc) = cur.take() {
                    finish(acc, &mut done)?;
                }
                if !seen.insert((t.to_string(), l.to_string())) {
                    return Err(IngestError::invalid(
                        path,
                        format!("profile {t}/{l}"),
                        "rows are not contiguous (the profile appears twice)",
                    ));
                }
                cur = Some(Acc {
                    key: (t.into(), l.into()),
                    x: Vec::new(),
                    z: Vec::new(),
                });
            }
            let acc = cur.as_mut().expect("set above");
            if acc.x.len() >= MAX_PROFILE_SAMPLES {
                return Err(IngestError::invalid(
                    path,
                    format!("profile {t}/{l}"),
                    format!("more than {MAX_PROFILE_SAMPLES} samples"),
                ));
            }
            acc.x.push(x.value(i));
            acc.z.push(z.value(i));
        }
    }
    if let Some(acc) = cur.take() {
        finish(acc, &mut done)?;
    }
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(track: &str, loc: &str, n: usize) -> Profile {
        Profile {
            track: track.into(),
            location: loc.into(),
            x0_mm: 0.0,
            dx_mm: 0.05,
            z_mm: (0..n).map(|i| (i as f64 * 0.3).sin()).collect(),
        }
    }

    #[test]
    fn csv_and_parquet_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let a = profile("monza", "L1", 64);
        let b = profile("spa", "L2", 40);
        write_profile_csv(&dir.path().join("a.csv"), &a).unwrap();
        let back = read_profile_csv(&dir.path().join("a.csv"), "monza", "L1").unwrap();
        assert_eq!(back.z_mm.len(), 64);
        assert!((back.dx_mm - 0.05).abs() < 1e-12);
        let pq = dir.path().join("p.parquet");
        write_profiles_parquet(&pq, &[a.clone(), b.clone()]).unwrap();
        let all = read_profiles_parquet(&pq).unwrap();
        assert_eq!(all.len(), 2);
        assert_eq!(all[1].track, "spa");
        assert_eq!(all[0].z_mm, a.z_mm);
    }

    #[test]
    fn unequal_spacing_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.csv");
        let mut text = String::from("x_mm,z_mm\n");
        for i in 0..20 {
            let x = if i == 7 { 0.9 } else { i as f64 * 0.125 };
            text += &format!("{x},{}\n", 0.1 * (i % 3) as f64);
        }
        std::fs::write(&path, text).unwrap();
        let err = read_profile_csv(&path, "t", "L1").unwrap_err().to_string();
        assert!(err.contains("bad.csv") && err.contains("sample 7"), "{err}");
    }

    /// The cases that panicked, aborted or gave NaN before the checks.
    #[test]
    fn absurd_profiles_are_refused_before_anything_is_sized_from_them() {
        let p = Path::new("road.csv");
        let x = |n: usize, dx: f64| (0..n).map(|i| i as f64 * dx).collect::<Vec<_>>();
        let z = |n: usize| (0..n).map(|i| (i as f64 * 0.7).sin()).collect::<Vec<_>>();
        let err = |x: &[f64], z: Vec<f64>| {
            Profile::from_columns("t", "L1", x, z, p)
                .unwrap_err()
                .to_string()
        };
        // 1e-300 mm and 1e-9 mm spacing: capacity overflow / a 600 GB filter before.
        assert!(err(&x(100, 1e-300), z(100)).contains("spacing"));
        assert!(err(&x(100_000, 1e-9), z(100_000)).contains("spacing"));
        // x in metres: 0.01 mm written as 1e-5.
        assert!(err(&x(4000, 1e-5), z(4000)).contains("is x in mm?"));
        // 16 points at 0.01 mm: 0.16 mm, too short for any texture index.
        assert!(err(&x(16, 0.01), z(16)).contains("length"));
        // Flat, and heights of ±3e300 mm.
        assert!(err(&x(400, 0.01), vec![0.0; 400]).contains("flat"));
        let mut huge = z(400);
        huge[3] = 3e300;
        assert!(err(&x(400, 0.01), huge).contains("sample 3"));
        // A real one passes.
        Profile::from_columns("t", "L1", &x(400, 0.01), z(400), p).unwrap();
    }
}
