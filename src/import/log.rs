//! Reading logger files into channels: MoTeC CSV exports, generic CSV,
//! Parquet (tables with a time column) and MoTeC `.ld` (channels at their
//! own rates). Formats in `docs/import.md`, "Log formats".

use super::error::ImportError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Header facts a log carries (empty when it has none).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogMeta {
    /// "MoTeC CSV", "CSV", "Parquet" or "MoTeC ld".
    pub format: String,
    pub venue: String,
    pub vehicle: String,
    pub driver: String,
    pub session: String,
    pub comment: String,
    /// `YYYY-MM-DD` when the log's date could be read.
    pub date: Option<String>,
    /// Seconds after midnight of the log's start, when known.
    pub time_of_day_s: Option<f64>,
    /// Every header key and value as written (MoTeC CSV; `.ldx` details).
    pub header: BTreeMap<String, String>,
    /// Beacon (lap marker) times, seconds from the log's start: a `.ld`
    /// log's `.ldx` sidecar.
    pub beacons_s: Vec<f64>,
}

/// One channel as the log stores it.
#[derive(Debug, Clone, PartialEq)]
pub struct RawChannel {
    pub name: String,
    /// As written ("" when the log gives none).
    pub unit: String,
    pub values: Vec<f64>,
    /// Sample rate (Hz) for logs whose channels have their own rates (`.ld`);
    /// `None` in a table, where a time column gives the times.
    pub rate_hz: Option<f64>,
}

/// A log file's channels.
#[derive(Debug, Clone, PartialEq)]
pub struct RawLog {
    pub path: PathBuf,
    pub meta: LogMeta,
    pub channels: Vec<RawChannel>,
}

impl RawLog {
    pub fn names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.name.clone()).collect()
    }
    pub fn units(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.unit.clone()).collect()
    }
    /// True for a table (one row per time step, a time column).
    pub(crate) fn tabular(&self) -> bool {
        self.channels.iter().all(|c| c.rate_hz.is_none())
    }
}

/// Largest log read (bytes): a larger file is refused, not loaded.
const MAX_LOG_BYTES: u64 = 8 << 30;

/// Reads a log, choosing the format by extension (`.ld`, `.parquet`,
/// `.csv`; a CSV whose first cell is `Format` and second `MoTeC CSV File` is
/// a MoTeC export).
pub fn read_log(path: &Path) -> Result<RawLog, ImportError> {
    let meta = std::fs::metadata(path).map_err(|e| ImportError::io(path, e))?;
    if !meta.is_file() {
        // A FIFO's open waits for a writer; a device has no end.
        return Err(ImportError::log(
            path,
            "file",
            "is not a regular file (a device, FIFO or folder)",
        ));
    }
    let len = meta.len();
    if len > MAX_LOG_BYTES {
        return Err(ImportError::log(
            path,
            "file",
            format!("{len} bytes is over the 8 GiB limit"),
        ));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "ld" => super::ld::read_ld(path),
        "parquet" | "pq" => read_parquet(path),
        "csv" | "txt" => read_csv(path),
        _ => Err(ImportError::log(
            path,
            "file",
            format!("unknown log format '.{ext}' (known: .ld, .csv, .parquet)"),
        )),
    }
}

fn cells(rec: &csv::StringRecord) -> Vec<String> {
    rec.iter().map(|c| c.trim().to_string()).collect()
}

fn blank(c: &[String]) -> bool {
    c.iter().all(|x| x.is_empty())
}

/// `dd/mm/yyyy`, `yyyy-mm-dd` or `dd.mm.yyyy` to `YYYY-MM-DD`.
pub(crate) fn parse_date(s: &str) -> Option<String> {
    let parts: Vec<&str> = s.trim().split(['/', '-', '.']).collect();
    if parts.len() != 3 {
        return None;
    }
    let n: Vec<u32> = parts
        .iter()
        .map(|p| p.trim().parse().ok())
        .collect::<Option<_>>()?;
    let (y, m, d) = if parts[0].len() == 4 {
        (n[0], n[1], n[2])
    } else {
        (n[2], n[1], n[0])
    };
    ((1900..3000).contains(&y) && (1..=12).contains(&m) && (1..=31).contains(&d))
        .then(|| format!("{y:04}-{m:02}-{d:02}"))
}

/// `h:mm:ss` with an optional `AM`/`PM` to seconds after midnight.
pub(crate) fn parse_time_of_day(s: &str) -> Option<f64> {
    let s = s.trim();
    let (clock, pm) = match s.to_ascii_uppercase() {
        u if u.ends_with("PM") => (s[..s.len() - 2].trim(), Some(true)),
        u if u.ends_with("AM") => (s[..s.len() - 2].trim(), Some(false)),
        _ => (s, None),
    };
    let p: Vec<f64> = clock
        .split(':')
        .map(|x| x.trim().parse().ok())
        .collect::<Option<_>>()?;
    if p.len() < 2 || p.len() > 3 {
        return None;
    }
    let mut h = p[0];
    match pm {
        Some(true) if h < 12.0 => h += 12.0,
        Some(false) if h == 12.0 => h = 0.0,
        _ => {}
    }
    let sec = h * 3600.0 + p[1] * 60.0 + p.get(2).copied().unwrap_or(0.0);
    (0.0..86_400.0).contains(&sec).then_some(sec)
}

fn parse_cell(path: &Path, row: usize, name: &str, cell: &str) -> Result<f64, ImportError> {
    if cell.is_empty() {
        return Ok(f64::NAN);
    }
    cell.parse::<f64>().map_err(|_| ImportError::Channel {
        path: path.to_path_buf(),
        channel: name.to_string(),
        what: format!("line {row}: '{cell}' is not a number"),
    })
}

/// Reads a CSV log: a MoTeC export or a generic table.
pub(crate) fn read_csv(path: &Path) -> Result<RawLog, ImportError> {
    let file = std::fs::File::open(path).map_err(|e| ImportError::io(path, e))?;
    let mut rows = CsvRows {
        path,
        records: csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .from_reader(std::io::BufReader::with_capacity(1 << 20, file))
            .into_records(),
    };
    let Some((_, first)) = rows.next("header")? else {
        return Err(ImportError::log(path, "file", "is empty"));
    };
    let motec = first
        .first()
        .is_some_and(|c| c.eq_ignore_ascii_case("Format"))
        && first.get(1).is_some_and(|c| c.contains("MoTeC CSV"));
    let mut meta = LogMeta {
        format: if motec { "MoTeC CSV" } else { "CSV" }.into(),
        ..LogMeta::default()
    };
    let (CsvHeader { names, mut units }, pending) = if motec {
        let header = motec_csv_header(&mut rows, first, &mut meta.header)?;
        (header, None)
    } else {
        table_header(&mut rows, first)?
    };
    check_channel_names(path, &names)?;
    let values = csv_values(&mut rows, &names, pending)?;
    if motec {
        meta.venue = meta.header.get("Venue").cloned().unwrap_or_default();
        meta.vehicle = meta.header.get("Vehicle").cloned().unwrap_or_default();
        meta.driver = meta.header.get("Driver").cloned().unwrap_or_default();
        meta.session = meta.header.get("Session").cloned().unwrap_or_default();
        meta.comment = meta.header.get("Comment").cloned().unwrap_or_default();
        meta.date = meta.header.get("Log Date").and_then(|d| parse_date(d));
        meta.time_of_day_s = meta
            .header
            .get("Log Time")
            .and_then(|t| parse_time_of_day(t));
    }
    units.resize(names.len(), String::new());
    Ok(RawLog {
        path: path.to_path_buf(),
        meta,
        channels: names
            .into_iter()
            .zip(units)
            .zip(values)
            .map(|((name, unit), values)| RawChannel {
                name,
                unit,
                values,
                rate_hz: None,
            })
            .collect(),
    })
}

/// A CSV file's rows, blank ones skipped, each with its line number.
struct CsvRows<'a> {
    path: &'a Path,
    records: csv::StringRecordsIntoIter<std::io::BufReader<std::fs::File>>,
}

/// A row's line number and its cells (trimmed).
type Row = (usize, Vec<String>);

/// A CSV log's channel names and their units (in order; units may be
/// fewer, the rest have none).
struct CsvHeader {
    names: Vec<String>,
    units: Vec<String>,
}

impl CsvRows<'_> {
    /// The next row that is not blank; a malformed one is an error naming
    /// its line and `what` was expected there.
    fn next(&mut self, what: &str) -> Result<Option<Row>, ImportError> {
        loop {
            match self.records.next() {
                None => return Ok(None),
                Some(Err(e)) => {
                    let line = e.position().map_or(0, |p| p.line() as usize);
                    return Err(ImportError::log(
                        self.path,
                        format!("line {line}"),
                        format!("{what}: {e}"),
                    ));
                }
                Some(Ok(r)) => {
                    let line = r.position().map_or(0, |p| p.line() as usize);
                    let c = cells(&r);
                    if !blank(&c) {
                        return Ok(Some((line, c)));
                    }
                }
            }
        }
    }
}

/// A MoTeC CSV export's header from its `first` row: rows of key/value
/// pairs (cells 0-1 and 4-5, into `header`) up to the row of channel
/// names, which starts with the time column, then the units row.
fn motec_csv_header(
    rows: &mut CsvRows,
    first: Vec<String>,
    header: &mut BTreeMap<String, String>,
) -> Result<CsvHeader, ImportError> {
    let mut row = first;
    loop {
        let is_names = row.first().is_some_and(|c| c.eq_ignore_ascii_case("Time"))
            && row.len() > 2
            && row
                .get(1)
                .is_some_and(|c| !c.is_empty() && c.parse::<f64>().is_err());
        if is_names {
            break;
        }
        for k in [0, 4] {
            if let (Some(key), Some(v)) = (row.get(k), row.get(k + 1))
                && !key.is_empty()
            {
                header.insert(key.clone(), v.clone());
            }
        }
        row = rows
            .next("header")?
            .ok_or_else(|| {
                ImportError::log(
                    rows.path,
                    "header",
                    "no row of channel names (starting with \"Time\")",
                )
            })?
            .1;
    }
    let units = rows
        .next("units row")?
        .ok_or_else(|| {
            ImportError::log(rows.path, "header", "no units row after the channel names")
        })?
        .1;
    Ok(CsvHeader { names: row, units })
}

/// A generic table's header: its `first` row names the channels, with
/// units in brackets ("Speed [km/h]") or in a second row that is not
/// numeric. Returns them with the second row where it is the first data
/// row.
fn table_header(
    rows: &mut CsvRows,
    first: Vec<String>,
) -> Result<(CsvHeader, Option<Row>), ImportError> {
    let split: Vec<(String, String)> = first
        .iter()
        .map(|n| match n.rfind(['[', '(']) {
            Some(i) if n.ends_with([']', ')']) => (
                n[..i].trim().to_string(),
                n[i + 1..n.len() - 1].trim().to_string(),
            ),
            _ => (n.clone(), String::new()),
        })
        .collect();
    let second = rows.next("data")?;
    let units_row = second
        .as_ref()
        .is_some_and(|(_, c)| c.first().is_some_and(|x| x.parse::<f64>().is_err()));
    let (units, pending) = if units_row {
        (second.expect("checked").1, None)
    } else {
        (split.iter().map(|s| s.1.clone()).collect(), second)
    };
    let names = split.into_iter().map(|s| s.0).collect();
    Ok((CsvHeader { names, units }, pending))
}

/// Every channel needs a name of its own.
fn check_channel_names(path: &Path, names: &[String]) -> Result<(), ImportError> {
    if names.iter().any(|n| n.is_empty()) {
        return Err(ImportError::log(
            path,
            "header",
            "a channel has an empty name",
        ));
    }
    let mut seen = std::collections::HashSet::new();
    if let Some(d) = names.iter().find(|n| !seen.insert(n.as_str())) {
        return Err(ImportError::Channel {
            path: path.to_path_buf(),
            channel: d.clone(),
            what: "appears twice in the header".into(),
        });
    }
    Ok(())
}

/// The data rows (`pending` first, where the header read one) as one
/// column of values per channel; an empty cell is NaN, a row of another
/// length or a cell that is not a number an error naming its line.
fn csv_values(
    rows: &mut CsvRows,
    names: &[String],
    pending: Option<Row>,
) -> Result<Vec<Vec<f64>>, ImportError> {
    let path = rows.path;
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut push = |line: usize, row: Vec<String>| -> Result<(), ImportError> {
        if row.len() != names.len() {
            return Err(ImportError::log(
                path,
                format!("line {line}"),
                format!(
                    "{} cells, the header names {} channels",
                    row.len(),
                    names.len()
                ),
            ));
        }
        for ((v, cell), name) in values.iter_mut().zip(&row).zip(names) {
            v.push(parse_cell(path, line, name, cell)?);
        }
        Ok(())
    };
    if let Some((line, row)) = pending {
        push(line, row)?;
    }
    while let Some((line, row)) = rows.next("data")? {
        push(line, row)?;
    }
    Ok(values)
}

/// Reads a Parquet table: every numeric column is a channel; a column's
/// unit is its field metadata `unit`, else a `[unit]` at the end of its name.
pub(crate) fn read_parquet(path: &Path) -> Result<RawLog, ImportError> {
    use arrow_array::Array;
    let bad = |what: String| ImportError::log(path, "file", what);
    // The footer's byte ranges checked as for every Parquet file read.
    let opened = crate::ingest::checksum::open_parquet(path)?;
    let schema = opened.schema().clone();
    let reader = opened.batches().map_err(|e| bad(e.to_string()))?;
    let mut channels: Vec<RawChannel> = Vec::new();
    let mut columns = Vec::new();
    for (i, f) in schema.fields().iter().enumerate() {
        if !f.data_type().is_numeric() {
            continue;
        }
        let (name, unit) = match f.metadata().get("unit") {
            Some(u) => (f.name().clone(), u.clone()),
            None => match f.name().rfind('[') {
                Some(j) if f.name().ends_with(']') => (
                    f.name()[..j].trim().to_string(),
                    f.name()[j + 1..f.name().len() - 1].trim().to_string(),
                ),
                _ => (f.name().clone(), String::new()),
            },
        };
        columns.push(i);
        channels.push(RawChannel {
            name,
            unit,
            values: Vec::new(),
            rate_hz: None,
        });
    }
    for batch in reader {
        let batch = batch.map_err(|e| bad(e.to_string()))?;
        for (ch, &i) in channels.iter_mut().zip(&columns) {
            let col = arrow_cast::cast(batch.column(i), &arrow_schema::DataType::Float64)
                .map_err(|e| bad(format!("column '{}': {e}", ch.name)))?;
            let col = col
                .as_any()
                .downcast_ref::<arrow_array::Float64Array>()
                .expect("cast to Float64");
            ch.values.extend((0..col.len()).map(|k| {
                if col.is_null(k) {
                    f64::NAN
                } else {
                    col.value(k)
                }
            }));
        }
    }
    Ok(RawLog {
        path: path.to_path_buf(),
        meta: LogMeta {
            format: "Parquet".into(),
            ..LogMeta::default()
        },
        channels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A log or sidecar that is a FIFO (whose open waits for a writer), a
    /// device or a folder is refused by name, not opened.
    #[cfg(unix)]
    #[test]
    fn a_log_that_is_no_regular_file_is_refused_not_opened() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("X.ld");
        crate::make_fifo(&fifo);
        let folder = dir.path().join("Y.csv");
        std::fs::create_dir(&folder).unwrap();
        for path in [fifo.as_path(), Path::new("/dev/zero"), folder.as_path()] {
            let e = read_log(path).expect_err("refused").to_string();
            assert!(
                e.contains(&path.display().to_string()) && e.contains("not a regular file"),
                "{e}"
            );
        }
        let sidecar = dir.path().join("X.ldx");
        crate::make_fifo(&sidecar);
        let e = super::super::ld::read_ldx(&sidecar).expect_err("refused");
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }

    #[test]
    fn dates_and_times_by_hand() {
        assert_eq!(parse_date("13/11/2005").as_deref(), Some("2005-11-13"));
        assert_eq!(parse_date("2026-03-02").as_deref(), Some("2026-03-02"));
        assert_eq!(parse_date("31.12.2024").as_deref(), Some("2024-12-31"));
        assert_eq!(parse_date("13/31/2005"), None);
        assert_eq!(
            parse_time_of_day("9:39:57 AM"),
            Some(9.0 * 3600.0 + 39.0 * 60.0 + 57.0)
        );
        assert_eq!(parse_time_of_day("1:00:00 PM"), Some(13.0 * 3600.0));
        assert_eq!(parse_time_of_day("12:30:00 AM"), Some(30.0 * 60.0));
        assert_eq!(parse_time_of_day("25:00:00"), None);
    }

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn generic_csv_units_in_brackets_or_a_second_row() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            "a.csv",
            "time [s],Speed (km/h),x\n0,36,\n0.1,72,2\n",
        );
        let log = read_csv(&p).unwrap();
        assert_eq!(log.names(), ["time", "Speed", "x"]);
        assert_eq!(log.units(), ["s", "km/h", ""]);
        assert_eq!(log.channels[1].values, [36.0, 72.0]);
        assert!(log.channels[2].values[0].is_nan());
        let p = write(dir.path(), "b.csv", "t,v\ns,m/s\n0,1\n1,2\n");
        let log = read_csv(&p).unwrap();
        assert_eq!(log.units(), ["s", "m/s"]);
        assert_eq!(log.channels[1].values, [1.0, 2.0]);
    }

    #[test]
    fn parquet_units_from_metadata_or_the_name() {
        use arrow_array::{Float32Array, Float64Array, RecordBatch, StringArray};
        use arrow_schema::{DataType, Field, Schema};
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("log.parquet");
        let schema = Schema::new(vec![
            Field::new("t", DataType::Float64, false).with_metadata(
                std::collections::HashMap::from([("unit".to_string(), "s".to_string())]),
            ),
            Field::new("Speed [km/h]", DataType::Float32, true),
            Field::new("driver", DataType::Utf8, false),
        ]);
        let batch = RecordBatch::try_new(
            std::sync::Arc::new(schema),
            vec![
                std::sync::Arc::new(Float64Array::from(vec![0.0, 0.05])),
                std::sync::Arc::new(Float32Array::from(vec![Some(36.0), None])),
                std::sync::Arc::new(StringArray::from(vec!["a", "b"])),
            ],
        )
        .unwrap();
        let f = std::fs::File::create(&p).unwrap();
        let mut w = parquet::arrow::ArrowWriter::try_new(f, batch.schema(), None).unwrap();
        w.write(&batch).unwrap();
        w.close().unwrap();
        let log = read_log(&p).unwrap();
        assert_eq!(log.meta.format, "Parquet");
        assert_eq!(log.names(), ["t", "Speed"], "text columns are not channels");
        assert_eq!(log.units(), ["s", "km/h"]);
        assert_eq!(log.channels[1].values[0], 36.0);
        assert!(
            log.channels[1].values[1].is_nan(),
            "a null is a missing value"
        );
    }

    #[test]
    fn bad_csv_names_the_line_and_channel() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "c.csv", "t,v\n0,1\n1,abc\n");
        let e = read_csv(&p).unwrap_err().to_string();
        assert!(
            e.contains("c.csv") && e.contains("'v'") && e.contains("line 3") && e.contains("abc"),
            "{e}"
        );
        let p = write(dir.path(), "d.csv", "t,v\n0,1\n1,2,3\n");
        let e = read_csv(&p).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("3 cells"), "{e}");
        let p = write(dir.path(), "e.csv", "t,v,v\n0,1,2\n");
        let e = read_csv(&p).unwrap_err().to_string();
        assert!(e.contains("twice"), "{e}");
        let e = read_log(&dir.path().join("x.xyz")).unwrap_err().to_string();
        assert!(e.contains("x.xyz"), "{e}");
    }
}
