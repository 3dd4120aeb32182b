//! The KPI database: one row per tire and run. Every column is declared once
//! here (name, type, meaning) and drives the row struct, the Parquet schema
//! and the CSV header. Units and formulas: docs/kpis.md.

use crate::ingest::IngestError;
use crate::{Axle, Wheel};
use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema};
use std::path::Path;
use std::sync::Arc;

/// The cell type of a text column: free text, or a typed position
/// ([`Wheel`], [`Axle`]) spelled as in the file.
pub(crate) trait TextCell: Sized {
    fn text(&self) -> &str;
    /// The cell read from a file; the error says what was wrong.
    fn parse_text(s: &str) -> Result<Self, String>;
}

impl TextCell for String {
    fn text(&self) -> &str {
        self
    }
    fn parse_text(s: &str) -> Result<Self, String> {
        Ok(s.to_string())
    }
}

impl TextCell for Wheel {
    fn text(&self) -> &str {
        self.name()
    }
    fn parse_text(s: &str) -> Result<Self, String> {
        s.parse()
    }
}

impl TextCell for Axle {
    fn text(&self) -> &str {
        self.name()
    }
    fn parse_text(s: &str) -> Result<Self, String> {
        s.parse()
    }
}

macro_rules! kpi_table {
    (text: [$($t:ident: $tt:ty),* $(,)?], numbers: [$($n:ident),* $(,)?]) => {
        /// One row of the KPI database (see docs/kpis.md for every column).
        #[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
        pub struct KpiRow {
            $(pub $t: $tt,)*
            $(pub $n: f64,)*
        }

        impl KpiRow {
            pub const TEXT_COLUMNS: &'static [&'static str] = &[$(stringify!($t)),*];
            pub const NUMBER_COLUMNS: &'static [&'static str] = &[$(stringify!($n)),*];

            /// Numeric columns by name.
            pub fn number(&self, name: &str) -> Option<f64> {
                match name {
                    $(stringify!($n) => Some(self.$n),)*
                    _ => None,
                }
            }

            /// Sets a numeric column by name; false if there is no such column.
            pub fn set_number(&mut self, name: &str, v: f64) -> bool {
                match name {
                    $(stringify!($n) => { self.$n = v; true })*
                    _ => false,
                }
            }

            /// Sets a text column by name: Ok(false) if there is no such
            /// column, an error if the value is not one the column holds
            /// (an unknown wheel position or axle).
            pub(crate) fn set_text(&mut self, name: &str, v: &str) -> Result<bool, String> {
                match name {
                    $(stringify!($t) => { self.$t = <$tt as TextCell>::parse_text(v)?; Ok(true) })*
                    _ => Ok(false),
                }
            }

            fn arrays(rows: &[KpiRow]) -> Vec<ArrayRef> {
                vec![
                    $(Arc::new(StringArray::from_iter_values(rows.iter().map(|r| r.$t.text()))) as ArrayRef,)*
                    $(Arc::new(Float64Array::from_iter_values(rows.iter().map(|r| r.$n))) as ArrayRef,)*
                ]
            }
        }
    };
}

kpi_table!(
    text: [
        event: String, track: String, car: String, run: String, wheel: Wheel, axle: Axle,
        compound: String, tire_set: String, quality: String,
    ],
    numbers: [
        // Table 4: telemetry
        t_surface_avg_c, t_surface_std_c, t_inner_avg_c, t_inner_std_c, t_track_avg_c, t_air_avg_c,
        fx_avg_n, fx_std_n, fy_avg_n, fy_std_n, fz_avg_n, fz_std_n,
        vsx_avg_mps, vsx_std_mps, vsy_avg_mps, vsy_std_mps,
        friction_energy_x_j, friction_energy_y_j, friction_energy_j, sliding_distance_m,
        camber_avg_deg, pressure_avg_pa, contact_patch_mm2, distance_m,
        // Table 3: road (track means)
        macro_wavelength_mm, micro_wavelength_mm, hurst, hurst_hdc, ra_macro_mm, ra_micro_mm,
        peakyness_mm, skewness, kurtosis, rq_mm, ra_mm,
        // Table 5: viscoelastic
        solicitation_frequency_hz, shifted_temperature_c, storage_modulus_mpa, loss_factor,
        // Target
        wear_mean_pct,
        // Data quality
        telemetry_duration_s, dropout_time_s, invalid_samples, worn_through_readings,
    ]
);

impl KpiRow {
    /// The row's tire and run, the key of the per-tire side tables.
    pub fn tire_run(&self) -> super::TireRun {
        (self.run.clone(), self.wheel)
    }
}

pub fn schema() -> Arc<Schema> {
    let mut fields: Vec<Field> = KpiRow::TEXT_COLUMNS
        .iter()
        .map(|n| Field::new(*n, DataType::Utf8, false))
        .collect();
    fields.extend(KpiRow::NUMBER_COLUMNS.iter().map(|n| {
        Field::new(*n, DataType::Float64, false).with_metadata(std::collections::HashMap::from([(
            "unit".to_string(),
            unit(n).to_string(),
        )]))
    }));
    Arc::new(Schema::new(fields))
}

/// The road KPIs (paper table 3): one value per track, NaN for a track
/// without a usable road profile.
pub const ROAD_KPIS: [&str; 11] = [
    "macro_wavelength_mm",
    "micro_wavelength_mm",
    "hurst",
    "hurst_hdc",
    "ra_macro_mm",
    "ra_micro_mm",
    "peakyness_mm",
    "skewness",
    "kurtosis",
    "rq_mm",
    "ra_mm",
];

/// The viscoelastic KPIs (paper table 5): they need the road's macro
/// wavelength, so they are NaN where the road KPIs are.
pub const VISCOELASTIC_KPIS: [&str; 4] = [
    "solicitation_frequency_hz",
    "shifted_temperature_c",
    "storage_modulus_mpa",
    "loss_factor",
];

/// Where `columns` hold road or viscoelastic KPIs: why a season may lack
/// them (appended to a message that names the columns).
pub(crate) fn road_hint(columns: &[&str]) -> &'static str {
    if columns
        .iter()
        .any(|c| ROAD_KPIS.contains(c) || VISCOELASTIC_KPIS.contains(c))
    {
        " (a track without road profiles leaves its road KPIs NaN, and the viscoelastic \
         ones, which need its macro wavelength: docs/formats.md section 4)"
    } else {
        ""
    }
}

/// The unit of a numeric column, from its name's suffix (the naming rule of
/// docs/kpis.md); "1" for dimensionless indices. Written into the Parquet
/// schema as field metadata `unit`, and checked by `tirewear predict`.
pub fn unit(column: &str) -> &'static str {
    const SUFFIXES: [(&str, &str); 13] = [
        ("_mm2", "mm^2"),
        ("_mm", "mm"),
        ("_mps", "m/s"),
        ("_m", "m"),
        ("_c", "degC"),
        ("_n", "N"),
        ("_j", "J"),
        ("_deg", "deg"),
        ("_pa", "Pa"),
        ("_hz", "Hz"),
        ("_mpa", "MPa"),
        ("_pct", "%"),
        ("_s", "s"),
    ];
    // Longest suffix first, so `_mpa` is not read as `_pa`.
    let mut best: Option<(&str, &str)> = None;
    for (suffix, u) in SUFFIXES {
        if column.ends_with(suffix) && best.is_none_or(|(b, _)| suffix.len() > b.len()) {
            best = Some((suffix, u));
        }
    }
    best.map_or("1", |(_, u)| u)
}

/// Column names of a KPI Parquet file with their `unit` metadata (None when
/// the file does not state one, e.g. a table written by another tool).
pub fn read_units(path: &Path) -> Result<Vec<(String, Option<String>)>, IngestError> {
    let (file, _) = crate::ingest::open_regular(path)?;
    if let Some(why) = crate::ingest::checksum::not_parquet(&file) {
        return Err(not_a_kpi_database(path, why));
    }
    let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| parquet_err(path, e))?;
    Ok(builder
        .schema()
        .fields()
        .iter()
        .map(|f| (f.name().clone(), f.metadata().get("unit").cloned()))
        .collect())
}

fn parquet_err(path: &Path, e: impl Into<parquet::errors::ParquetError>) -> IngestError {
    IngestError::Parquet {
        path: path.to_path_buf(),
        source: e.into(),
    }
}

/// The record batches of a side table, each error naming the file.
pub(crate) fn side_batches(
    path: &Path,
) -> Result<impl Iterator<Item = Result<RecordBatch, IngestError>> + use<>, IngestError> {
    let reader = crate::ingest::checksum::open_parquet(path)?
        .batches()
        .map_err(|e| parquet_err(path, e))?;
    let path = path.to_path_buf();
    Ok(reader.map(move |b| b.map_err(|e| parquet_err(&path, e))))
}

/// The cells of each tire's maps a side table has given so far: a side
/// table holds each tire's non-empty cells once, and a cell given twice
/// (a damaged or hand-made file) would otherwise be added up into a map
/// silently.
pub(crate) struct CellsGiven {
    cells: usize,
    given: std::collections::HashMap<super::TireRun, Vec<u64>>,
}

impl CellsGiven {
    /// For maps of `cells` cells per tire.
    pub(crate) fn new(cells: usize) -> CellsGiven {
        CellsGiven {
            cells,
            given: Default::default(),
        }
    }

    /// Notes `cell` (below the `cells` of [`CellsGiven::new`]) of `tire`:
    /// false when the table gave it before.
    pub(crate) fn first(&mut self, tire: &super::TireRun, cell: usize) -> bool {
        let words = self.cells.div_ceil(64);
        let bits = match self.given.get_mut(tire) {
            Some(bits) => bits,
            None => self.given.entry(tire.clone()).or_insert(vec![0; words]),
        };
        let (word, bit) = (cell / 64, 1u64 << (cell % 64));
        let first = bits[word] & bit == 0;
        bits[word] |= bit;
        first
    }
}

/// Schema metadata key that ties the outputs of one extraction together
/// (the KPI table, its side tables and its report carry the same value).
pub(crate) const EXTRACTION_ID_KEY: &str = "tirewear.extraction_id";

/// `batch` with `extraction_id` in its schema metadata.
pub(crate) fn with_extraction_id(batch: RecordBatch, extraction_id: &str) -> RecordBatch {
    let mut meta = batch.schema().metadata().clone();
    meta.insert(EXTRACTION_ID_KEY.to_string(), extraction_id.to_string());
    let schema = Arc::new(batch.schema().as_ref().clone().with_metadata(meta));
    batch.with_schema(schema).expect("only metadata changed")
}

/// The extraction id a Parquet file was written with (None for files from
/// before ids, or from another tool).
pub fn read_extraction_id(path: &Path) -> Result<Option<String>, IngestError> {
    let (file, _) = crate::ingest::open_regular(path)?;
    if let Some(why) = crate::ingest::checksum::not_parquet(&file) {
        return Err(IngestError::invalid(path, "file", why));
    }
    let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| parquet_err(path, e))?;
    Ok(builder.schema().metadata().get(EXTRACTION_ID_KEY).cloned())
}

/// Refuses to pair a KPI table with a side table from another extraction
/// (a set mixed by a killed run, or files copied together by hand). Files
/// without an id (older than ids) pass.
pub fn check_same_extraction(kpis: &Path, side: &Path) -> Result<(), IngestError> {
    match (read_extraction_id(kpis)?, read_extraction_id(side)?) {
        (Some(a), Some(b)) if a != b => Err(IngestError::invalid(
            side,
            EXTRACTION_ID_KEY,
            format!(
                "is {b}, but {} comes from extraction {a}: the two files are from \
                 different extractions (run extract again)",
                kpis.display()
            ),
        )),
        _ => Ok(()),
    }
}

/// Writes a record batch as zstd Parquet into an open file (or a buffer).
pub(crate) fn write_batch_to(
    file: impl std::io::Write + Send,
    batch: &RecordBatch,
) -> std::io::Result<()> {
    write_batches_to(file, &batch.schema(), std::slice::from_ref(batch))
}

/// [`write_batch_to`] of the rows of `batches` one after the other, under
/// `schema` (their columns' types; its metadata is the file's): the same
/// file as their concatenation gives, without that copy of the whole
/// table (a night's commit of thousands of runs' parts; tested).
pub(crate) fn write_batches_to(
    file: impl std::io::Write + Send,
    schema: &arrow_schema::SchemaRef,
    batches: &[RecordBatch],
) -> std::io::Result<()> {
    write_with(file, schema, batches, Codec::Zstd)
}

/// Writes a night's part of one run (`process`'s staging) as LZ4 Parquet.
///
/// The Parquet crate makes a zstd compressor and decompressor for every
/// column chunk it writes or reads (`ZSTD_createCCtx`, `ZSTD_createDCtx`:
/// 21 % of a night of 4 320 short runs, whose parts hold a few to a few
/// thousand rows, the KPI part in 53 columns). LZ4 has no context to make;
/// the dataset takes some 5 % more disk (docs/nightly.md, "Many runs").
pub(crate) fn write_part_to(
    file: impl std::io::Write + Send,
    batch: &RecordBatch,
) -> std::io::Result<()> {
    write_with(
        file,
        &batch.schema(),
        std::slice::from_ref(batch),
        Codec::Lz4,
    )
}

/// [`write_row_groups`] in row groups of the Parquet crate's default size.
fn write_with(
    file: impl std::io::Write + Send,
    schema: &arrow_schema::SchemaRef,
    batches: &[RecordBatch],
    codec: Codec,
) -> std::io::Result<()> {
    write_row_groups(
        file,
        schema,
        batches,
        parquet::file::properties::DEFAULT_MAX_ROW_GROUP_ROW_COUNT,
        codec,
    )
    .map_err(std::io::Error::other)
}

/// The compression of a Parquet file tirewear writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Codec {
    /// The tables users keep and move: KPI and side tables, a dataset's
    /// committed tables.
    Zstd,
    /// A night's parts, each written once and read at each commit.
    Lz4,
}

/// How tirewear's Parquet files are written: zstd, row groups of
/// `rows_per_group`, and no dictionary for f64 columns. Energies and
/// indices are nearly all distinct, so a dictionary only adds the hashing
/// of every value and an index per row for zstd to compress: without it
/// the demo's condition maps encode in 32 ms rather than 38, and every
/// table is smaller (condition maps 2.96 → 2.67 MB, KPIs 98 → 86 KB).
fn writer_properties(
    schema: &arrow_schema::Schema,
    rows_per_group: usize,
    codec: Codec,
) -> parquet::file::properties::WriterProperties {
    let compression = match codec {
        Codec::Zstd => parquet::basic::Compression::ZSTD(Default::default()),
        Codec::Lz4 => parquet::basic::Compression::LZ4_RAW,
    };
    let mut props = parquet::file::properties::WriterProperties::builder()
        .set_compression(compression)
        .set_max_row_group_row_count(Some(rows_per_group));
    for f in schema.fields() {
        if f.data_type() == &DataType::Float64 {
            let column = parquet::schema::types::ColumnPath::from(f.name().as_str());
            props = props.set_column_dictionary_enabled(column, false);
        }
    }
    props.build()
}

/// The file `ArrowWriter` writes (its schema, metadata and column
/// writers), but each row group's columns are encoded on rayon threads at
/// once: a big side table (the condition maps', 933 000 rows at season
/// scale) is otherwise encoded on one thread after every run is done.
fn write_row_groups(
    file: impl std::io::Write + Send,
    schema: &arrow_schema::SchemaRef,
    batches: &[RecordBatch],
    rows_per_group: usize,
    codec: Codec,
) -> parquet::errors::Result<()> {
    use parquet::arrow::arrow_writer::{ArrowColumnChunk, compute_leaves};
    use rayon::prelude::*;
    let props = writer_properties(schema, rows_per_group, codec);
    let sink = crate::ingest::checksum::CrcWriter::new(file);
    let w = parquet::arrow::ArrowWriter::try_new(sink, schema.clone(), Some(props))?;
    let (mut file_writer, columns) = w.into_serialized_writer()?;
    let rows: usize = batches.iter().map(|b| b.num_rows()).sum();
    let mut at = (0, 0);
    for (group, start) in (0..rows).step_by(rows_per_group.max(1)).enumerate() {
        let part = next_rows(schema, batches, &mut at, rows_per_group.min(rows - start))?;
        let mut leaves = Vec::new();
        for (field, column) in schema.fields().iter().zip(part.columns()) {
            leaves.extend(compute_leaves(field, column)?);
        }
        let writers = columns.create_column_writers(group)?;
        if writers.len() != leaves.len() {
            return Err(parquet::errors::ParquetError::General(format!(
                "{} column writers for {} leaf columns",
                writers.len(),
                leaves.len()
            )));
        }
        let chunks = writers
            .into_par_iter()
            .zip(leaves)
            .map(|(mut writer, leaf)| {
                writer.write(&leaf)?;
                writer.close()
            })
            .collect::<parquet::errors::Result<Vec<ArrowColumnChunk>>>()?;
        let mut row_group = file_writer.next_row_group()?;
        for chunk in chunks {
            chunk.append_to_row_group(&mut row_group)?;
        }
        row_group.close()?;
    }
    crate::ingest::checksum::seal(&mut file_writer)?;
    file_writer.close()?;
    Ok(())
}

/// The next `count` rows of `batches` from `at` (batch, row), which it
/// moves past them: a slice of one batch, or the slices of several
/// concatenated under `schema`.
fn next_rows(
    schema: &arrow_schema::SchemaRef,
    batches: &[RecordBatch],
    at: &mut (usize, usize),
    count: usize,
) -> parquet::errors::Result<RecordBatch> {
    let mut pieces = Vec::new();
    let mut left = count;
    while left > 0 {
        let Some(batch) = batches.get(at.0) else {
            break;
        };
        let n = (batch.num_rows() - at.1).min(left);
        if n > 0 {
            pieces.push(batch.slice(at.1, n));
        }
        at.1 += n;
        left -= n;
        if at.1 == batch.num_rows() {
            *at = (at.0 + 1, 0);
        }
    }
    match pieces.len() {
        1 => Ok(pieces.pop().expect("one piece")),
        _ => Ok(arrow_select::concat::concat_batches(schema, &pieces)?),
    }
}

/// Writes a record batch to a zstd Parquet file, atomically.
pub fn write_batch(path: &Path, batch: &RecordBatch) -> Result<(), IngestError> {
    crate::atomic::write_file(path, |f| write_batch_to(f, batch))
        .map_err(|e| IngestError::io(path, e))
}

/// The KPI rows as one record batch (the Parquet table's schema).
pub(crate) fn kpi_batch(rows: &[KpiRow]) -> RecordBatch {
    RecordBatch::try_new(schema(), KpiRow::arrays(rows)).expect("columns match the schema")
}

/// Writes the KPI rows as Parquet (the extraction writes its batches
/// through `write_batch`; tests write rows directly).
#[cfg(test)]
pub(crate) fn write_parquet(path: &Path, rows: &[KpiRow]) -> Result<(), IngestError> {
    write_batch(path, &kpi_batch(rows))
}

/// Writes the KPI rows as CSV (same columns).
pub fn write_csv(path: &Path, rows: &[KpiRow]) -> Result<(), IngestError> {
    crate::atomic::write_csv(path, rows).map_err(|e| IngestError::io(path, e))
}

/// Numeric columns added after the first KPI files were written: an older
/// file without them reads them as 0.
pub(crate) const LATER_COLUMNS: [&str; 1] = ["worn_through_readings"];

/// Text columns added later: an older file without them reads them as "".
pub(crate) const LATER_TEXT_COLUMNS: [&str; 1] = ["quality"];

/// `quality` of a row whose every number is finite.
pub const QUALITY_OK: &str = "ok";

/// The `quality` column: [`QUALITY_OK`] when every numeric column is finite,
/// else the known reasons and the non-finite columns, `; `-separated
/// (docs/kpis.md, "Data quality").
pub fn quality(row: &KpiRow, reasons: &[String]) -> String {
    let bad: Vec<&str> = KpiRow::NUMBER_COLUMNS
        .iter()
        .copied()
        .filter(|n| !row.number(n).is_some_and(f64::is_finite))
        .collect();
    if bad.is_empty() {
        return QUALITY_OK.to_string();
    }
    let mut parts: Vec<String> = reasons.to_vec();
    parts.push(format!("not finite: {}", bad.join(", ")));
    parts.join("; ")
}

/// The `quality` of a run `tirewear import` wrote: `estimated: CHANNELS`
/// (the channels its virtual sensors estimated, from the telemetry's
/// `tirewear.import` record) in place of `ok`, or after the other reasons.
pub(crate) fn with_estimated(quality: &str, estimated: &str) -> String {
    let names: Vec<&str> = estimated
        .split("; ")
        .filter_map(|part| part.split(':').next())
        .map(str::trim)
        .filter(|n| !n.is_empty())
        .collect();
    let est = format!("estimated: {}", names.join(", "));
    if quality == QUALITY_OK {
        est
    } else {
        format!("{quality}; {est}")
    }
}

/// Casts a column to `to`, refusing nulls and values that do not convert
/// (a text cell "abc" in a numeric column): the error names the column and
/// the row (0-based over the file), instead of reading them as 0.
fn strict_cast(
    path: &Path,
    name: &str,
    col: &ArrayRef,
    to: &DataType,
    first_row: usize,
) -> Result<ArrayRef, IngestError> {
    let bad = |row: usize, what: String| {
        IngestError::invalid(path, format!("column '{name}', row {row}"), what)
    };
    if let Some(i) = (0..col.len()).find(|&i| col.is_null(i)) {
        return Err(bad(first_row + i, "is empty (null)".into()));
    }
    let lenient = arrow_cast::cast(col, to).map_err(|e| parquet_err(path, e))?;
    if let Some(i) = (0..lenient.len()).find(|&i| lenient.is_null(i)) {
        let cell = arrow_cast::display::ArrayFormatter::try_new(col.as_ref(), &Default::default())
            .map(|f| f.value(i).to_string())
            .unwrap_or_default();
        return Err(bad(first_row + i, format!("'{cell}' is not a {to}")));
    }
    Ok(lenient)
}

/// Column `name` of a record batch cast to `to` by [`strict_cast`]: a
/// missing column, a null or a value that does not convert is an error
/// naming the column and the row (`first_row` is the batch's first row in
/// the file). For the side-table readers.
pub(crate) fn checked_column(
    path: &Path,
    batch: &RecordBatch,
    name: &str,
    to: &DataType,
    first_row: usize,
) -> Result<ArrayRef, IngestError> {
    let col = batch
        .column_by_name(name)
        .ok_or_else(|| IngestError::invalid(path, "schema", format!("missing column '{name}'")))?;
    strict_cast(path, name, col, to, first_row)
}

/// Checks each numeric column's `unit` metadata, where the file states one,
/// against the unit this build expects: a table in other units is refused
/// rather than read as numbers in ours.
fn check_units(path: &Path, schema: &Schema) -> Result<(), IngestError> {
    for f in schema.fields() {
        let name = f.name();
        if !KpiRow::NUMBER_COLUMNS.contains(&name.as_str()) {
            continue;
        }
        if let Some(u) = f.metadata().get("unit")
            && u != unit(name)
        {
            return Err(IngestError::invalid(
                path,
                format!("column '{name}'"),
                format!("unit is '{u}', tirewear expects '{}'", unit(name)),
            ));
        }
    }
    Ok(())
}

/// A side table of the KPI database at `kpis` (`NAME.SUFFIX` beside
/// `NAME.parquet`: `road.parquet`, `energy_maps.parquet`,
/// `condition_maps.parquet`, `report.json`; docs/formats.md).
pub fn side_table_path(kpis: &Path, suffix: &str) -> std::path::PathBuf {
    let stem = kpis.file_stem().and_then(|s| s.to_str()).unwrap_or("kpis");
    kpis.with_file_name(format!("{stem}.{suffix}"))
}

/// The error for a KPI database that is not a Parquet file (`why`), with
/// the Parquet file beside it where there is one: the CSV copy `extract`
/// writes is a natural first try.
fn not_a_kpi_database(path: &Path, why: String) -> IngestError {
    let parquet = path.with_extension("parquet");
    let hint = if parquet != path && parquet.is_file() {
        format!(
            "; the KPI database is the Parquet file beside it (`extract` writes a CSV \
             copy for reading by eye): did you mean {}?",
            parquet.display()
        )
    } else {
        String::new()
    };
    IngestError::invalid(path, "file", format!("{why}{hint}"))
}

/// As [`read_parquet`], for a command that learns from the rows (`fit`,
/// `gap`): a table without rows is an error saying where it came from,
/// rather than each method's "no training rows" or "got 0 observations".
/// (`extract` writes none since 2026-12-02; a night whose every run failed
/// before any was committed still commits one, and older versions wrote
/// them.)
pub fn read_parquet_rows(path: &Path) -> Result<Vec<KpiRow>, IngestError> {
    let rows = read_parquet(path)?;
    if rows.is_empty() {
        // A `process` dataset's summary, else `extract`'s report.
        let summary = path.with_file_name("summary.json");
        let why = if summary.is_file() {
            summary
        } else {
            side_table_path(path, "report.json")
        };
        return Err(IngestError::invalid(
            path,
            "rows",
            format!(
                "the KPI table has no rows: every run of the extraction or night that wrote it \
                 failed or was skipped ({} says why)",
                why.display()
            ),
        ));
    }
    Ok(rows)
}

/// Reads a KPI Parquet file back (for `fit`, `predict`, `gap` and tests).
/// Nulls, cells of the wrong type and columns in other units are errors
/// naming the column (and row).
pub fn read_parquet(path: &Path) -> Result<Vec<KpiRow>, IngestError> {
    if path.is_dir() {
        // Opening a folder fails late, inside the Parquet reader, with a bare
        // "Is a directory"; say what was expected instead.
        let hint = path.join("kpis.parquet");
        let hint = if hint.is_file() {
            format!("; did you mean {}?", hint.display())
        } else {
            String::new()
        };
        return Err(IngestError::invalid(
            path,
            "file",
            format!("is a folder, not a KPI database (the Parquet file `extract` writes){hint}"),
        ));
    }
    let opened = crate::ingest::checksum::open_parquet(path).map_err(|e| match e {
        // `open_parquet`'s refusal of a file that is not Parquet.
        IngestError::Invalid { record, what, .. } if record == "file" && what.contains("PAR1") => {
            not_a_kpi_database(path, what)
        }
        e => e,
    })?;
    check_units(path, opened.schema())?;
    let reader = opened.batches().map_err(|e| parquet_err(path, e))?;
    let mut rows = Vec::new();
    for batch in reader {
        let batch = batch.map_err(|e| parquet_err(path, e))?;
        let first_row = rows.len();
        let column = |name: &str| {
            batch.column_by_name(name).ok_or_else(|| {
                IngestError::invalid(path, "schema", format!("missing column '{name}'"))
            })
        };
        let text = |name: &str| -> Result<StringArray, IngestError> {
            let cast = strict_cast(path, name, column(name)?, &DataType::Utf8, first_row)?;
            Ok(cast
                .as_any()
                .downcast_ref::<StringArray>()
                .expect("cast")
                .clone())
        };
        let num = |name: &str| -> Result<Float64Array, IngestError> {
            let cast = strict_cast(path, name, column(name)?, &DataType::Float64, first_row)?;
            Ok(cast
                .as_any()
                .downcast_ref::<Float64Array>()
                .expect("cast")
                .clone())
        };
        // Columns added after the first files were written read as a default when absent.
        let texts = KpiRow::TEXT_COLUMNS
            .iter()
            .map(|n| match text(n) {
                Err(_) if LATER_TEXT_COLUMNS.contains(n) && batch.column_by_name(n).is_none() => {
                    Ok(StringArray::from(vec![""; batch.num_rows()]))
                }
                other => other,
            })
            .collect::<Result<Vec<_>, _>>()?;
        let nums = KpiRow::NUMBER_COLUMNS
            .iter()
            .map(|n| match num(n) {
                Err(_) if LATER_COLUMNS.contains(n) && batch.column_by_name(n).is_none() => {
                    Ok(Float64Array::from(vec![0.0; batch.num_rows()]))
                }
                other => other,
            })
            .collect::<Result<Vec<_>, _>>()?;
        for i in 0..batch.num_rows() {
            let mut r = KpiRow::default();
            for (n, a) in KpiRow::TEXT_COLUMNS.iter().zip(&texts) {
                r.set_text(n, a.value(i)).map_err(|e| {
                    IngestError::invalid(path, format!("column '{n}', row {}", first_row + i), e)
                })?;
            }
            for (n, a) in KpiRow::NUMBER_COLUMNS.iter().zip(&nums) {
                r.set_number(n, a.value(i));
            }
            rows.push(r);
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ArrowWriter` itself, the route `write_row_groups` replaces, sealed
    /// with the data checksum as the road profiles' writer seals it.
    fn arrow_writer_bytes(batch: &RecordBatch, rows_per_group: usize, codec: Codec) -> Vec<u8> {
        use crate::ingest::checksum::{CrcWriter, seal_arrow};
        let props = writer_properties(&batch.schema(), rows_per_group, codec);
        let mut out = Vec::new();
        let sink = CrcWriter::new(&mut out);
        let mut w =
            parquet::arrow::ArrowWriter::try_new(sink, batch.schema(), Some(props)).unwrap();
        w.write(batch).unwrap();
        seal_arrow(&mut w).unwrap();
        w.close().unwrap();
        out
    }

    #[test]
    fn columns_encoded_at_once_write_the_file_arrow_writer_writes() {
        use arrow_array::UInt32Array;
        let n = 2_500;
        let schema = Schema::new(vec![
            Field::new("run", DataType::Utf8, false),
            Field::new("bin", DataType::UInt32, false),
            Field::new("energy_j", DataType::Float64, true),
        ])
        .with_metadata(std::collections::HashMap::from([(
            "tirewear.test".to_string(),
            "1".to_string(),
        )]));
        let energy: Float64Array = (0..n)
            .map(|i| match i % 7 {
                0 => None,
                1 => Some(f64::NAN),
                _ => Some(i as f64 * 0.37 - 100.0),
            })
            .collect();
        let batch = RecordBatch::try_new(
            Arc::new(schema),
            vec![
                Arc::new(StringArray::from_iter_values(
                    (0..n).map(|i| format!("run{}", i / 13)),
                )),
                Arc::new(UInt32Array::from_iter_values((0..n).map(|i| i as u32 % 40))),
                Arc::new(energy),
            ],
        )
        .unwrap();
        // One row group, several with a short last one, and an empty table.
        for codec in [Codec::Zstd, Codec::Lz4] {
            for (rows, per_group) in [(n, 1 << 20), (n, 1_000), (0, 1_000)] {
                let part = batch.slice(0, rows);
                let mut ours = Vec::new();
                write_row_groups(
                    &mut ours,
                    &part.schema(),
                    std::slice::from_ref(&part),
                    per_group,
                    codec,
                )
                .unwrap();
                assert_eq!(
                    ours,
                    arrow_writer_bytes(&part, per_group, codec),
                    "{codec:?}: {rows} rows, {per_group} a group"
                );
            }
        }
        // The rows given as several batches (a commit's parts: of 1, 0,
        // 999, 1 001 … rows, so that row groups start inside batches and
        // span several) write the file their concatenation writes, under
        // the schema given (with its metadata), whatever the batches'.
        let sizes = [1, 0, 999, 1_001, 7, 0, 492];
        let mut batches = Vec::new();
        let mut start = 0;
        for size in sizes {
            let cut = batch.slice(start, size);
            let bare = Arc::new(Schema::new(cut.schema().fields().clone()));
            batches.push(RecordBatch::try_new(bare, cut.columns().to_vec()).unwrap());
            start += size;
        }
        let whole = batch.slice(0, start);
        for per_group in [1 << 20, 1_000, 333] {
            let mut ours = Vec::new();
            write_row_groups(&mut ours, &batch.schema(), &batches, per_group, Codec::Zstd).unwrap();
            assert_eq!(
                ours,
                arrow_writer_bytes(&whole, per_group, Codec::Zstd),
                "{per_group} a group, from {} batches",
                batches.len()
            );
        }
    }

    /// The written file's own footer, read back by the Parquet reader: the
    /// f64 column has no dictionary page, the string and integer ones keep
    /// theirs, and the values read back unchanged.
    #[test]
    fn f64_columns_are_written_without_a_dictionary() {
        use arrow_array::UInt32Array;
        use parquet::file::reader::{FileReader, SerializedFileReader};
        let n = 3_000;
        let schema = Schema::new(vec![
            Field::new("run", DataType::Utf8, false),
            Field::new("bin", DataType::UInt32, false),
            Field::new("energy_j", DataType::Float64, false),
        ]);
        let energy = Float64Array::from_iter_values((0..n).map(|i| (i % 5) as f64 * 0.5));
        let batch = RecordBatch::try_new(
            Arc::new(schema),
            vec![
                Arc::new(StringArray::from_iter_values(
                    (0..n).map(|i| format!("run{}", i / 100)),
                )),
                Arc::new(UInt32Array::from_iter_values((0..n).map(|i| i as u32 % 40))),
                Arc::new(energy.clone()),
            ],
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        write_batch_to(std::fs::File::create(&path).unwrap(), &batch).unwrap();
        let file = SerializedFileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
        let group = file.metadata().row_group(0);
        let dictionary: Vec<bool> = (0..3)
            .map(|c| group.column(c).dictionary_page_offset().is_some())
            .collect();
        assert_eq!(dictionary, [true, true, false]);
        let back = parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(
            std::fs::File::open(&path).unwrap(),
            4096,
        )
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
        let read = back
            .column(2)
            .as_any()
            .downcast_ref::<Float64Array>()
            .unwrap();
        assert_eq!(read, &energy);
    }

    #[test]
    fn files_without_later_columns_read_them_as_zero() {
        let rows = vec![
            KpiRow {
                run: "R1".into(),
                wear_mean_pct: 12.5,
                worn_through_readings: 3.0,
                ..Default::default()
            };
            2
        ];
        let dir = tempfile::tempdir().unwrap();
        // As written today: the column round-trips.
        let now = dir.path().join("now.parquet");
        write_parquet(&now, &rows).unwrap();
        assert_eq!(read_parquet(&now).unwrap()[0].worn_through_readings, 3.0);
        // An older file: the same table without `worn_through_readings`.
        let full = RecordBatch::try_new(schema(), KpiRow::arrays(&rows)).unwrap();
        let keep: Vec<usize> = (0..full.num_columns())
            .filter(|&i| full.schema().field(i).name() != "worn_through_readings")
            .collect();
        let old = dir.path().join("old.parquet");
        write_batch(&old, &full.project(&keep).unwrap()).unwrap();
        let back = read_parquet(&old).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(
            (back[0].wear_mean_pct, back[0].worn_through_readings),
            (12.5, 0.0)
        );
        // Any other missing column is still an error naming it.
        let keep: Vec<usize> = (0..full.num_columns())
            .filter(|&i| full.schema().field(i).name() != "hurst")
            .collect();
        write_batch(&old, &full.project(&keep).unwrap()).unwrap();
        let err = read_parquet(&old).unwrap_err().to_string();
        assert!(err.contains("missing column 'hurst'"), "{err}");
    }

    /// A table without rows (a night whose every run failed before any
    /// was committed) reads as empty, but `fit` and `gap` are told where
    /// it came from instead of "no training rows" or "got 0".
    #[test]
    fn a_table_without_rows_is_named_for_fit_and_gap() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("kpis.parquet");
        write_parquet(&path, &[]).unwrap();
        assert!(read_parquet(&path).unwrap().is_empty());
        let e = read_parquet_rows(&path).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!(
                "{}: rows: the KPI table has no rows",
                path.display()
            )),
            "{e}"
        );
        let report = dir.path().join("kpis.report.json");
        assert!(
            e.ends_with(&format!("({} says why)", report.display())),
            "{e}"
        );
        // In a `process` dataset, its summary.
        std::fs::write(dir.path().join("summary.json"), "{}").unwrap();
        let e = read_parquet_rows(&path).unwrap_err().to_string();
        assert!(e.ends_with("summary.json says why)"), "{e}");
        write_parquet(&path, &[KpiRow::default()]).unwrap();
        assert_eq!(read_parquet_rows(&path).unwrap().len(), 1);
    }

    /// The CSV copy handed in for the KPI database is refused, for what it
    /// is, pointing to the Parquet file beside it: by the reader of rows, of
    /// units and of the extraction id. Without a Parquet file beside it
    /// there is no pointer.
    #[test]
    fn the_csv_copy_is_refused_naming_the_parquet_file_beside_it() {
        let rows = vec![KpiRow::default(); 2];
        let dir = tempfile::tempdir().unwrap();
        let (parquet, csv) = (dir.path().join("kpis.parquet"), dir.path().join("kpis.csv"));
        write_parquet(&parquet, &rows).unwrap();
        write_csv(&csv, &rows).unwrap();
        let pointer = format!("did you mean {}?", parquet.display());
        for err in [
            read_parquet(&csv).unwrap_err(),
            read_units(&csv).unwrap_err(),
        ] {
            let err = err.to_string();
            assert!(err.starts_with(&format!("{}: file: is not a Parquet file", csv.display())));
            assert!(
                err.contains("it is text, beginning `event,track,car,run,"),
                "{err}"
            );
            assert!(err.ends_with(&pointer), "{err}");
        }
        let err = read_extraction_id(&csv).unwrap_err().to_string();
        assert!(err.contains("is not a Parquet file"), "{err}");
        std::fs::remove_file(&parquet).unwrap();
        let err = read_parquet(&csv).unwrap_err().to_string();
        assert!(
            err.contains("it is text") && !err.contains("did you mean"),
            "{err}"
        );
    }

    #[test]
    fn units_follow_the_suffix_rule() {
        assert_eq!(unit("storage_modulus_mpa"), "MPa");
        assert_eq!(unit("pressure_avg_pa"), "Pa");
        assert_eq!(unit("contact_patch_mm2"), "mm^2");
        assert_eq!(unit("ra_mm"), "mm");
        assert_eq!(unit("vsx_avg_mps"), "m/s");
        assert_eq!(unit("distance_m"), "m");
        assert_eq!(unit("t_surface_avg_c"), "degC");
        assert_eq!(unit("friction_energy_j"), "J");
        assert_eq!(unit("wear_mean_pct"), "%");
        assert_eq!(unit("skewness"), "1");
        assert_eq!(unit("invalid_samples"), "1");
        assert!(schema().fields().iter().all(|f| f.data_type() == &DataType::Utf8
            || f.metadata()["unit"] == unit(f.name())));
    }

    /// Replaces column `name` of the table of `rows` by `col` (with `field`).
    fn with_column(rows: &[KpiRow], name: &str, field: Field, col: ArrayRef) -> RecordBatch {
        let full = kpi_batch(rows);
        let i = full.schema().index_of(name).unwrap();
        let mut fields: Vec<Field> = full
            .schema()
            .fields()
            .iter()
            .map(|f| f.as_ref().clone())
            .collect();
        let mut cols = full.columns().to_vec();
        fields[i] = field;
        cols[i] = col;
        RecordBatch::try_new(Arc::new(Schema::new(fields)), cols).unwrap()
    }

    #[test]
    fn wheels_and_axles_are_typed_and_an_unknown_one_is_named() {
        let rows = vec![
            KpiRow {
                run: "R1".into(),
                wheel: Wheel::RR,
                axle: Axle::Rear,
                ..Default::default()
            };
            3
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("k.parquet");
        // Written as the documented spellings, and read back typed.
        write_parquet(&path, &rows).unwrap();
        let back = read_parquet(&path).unwrap();
        assert_eq!((back[2].wheel, back[2].axle), (Wheel::RR, Axle::Rear));
        let batch = kpi_batch(&rows);
        let text = |name: &str| {
            let c = batch.column_by_name(name).unwrap();
            c.as_any()
                .downcast_ref::<StringArray>()
                .unwrap()
                .value(0)
                .to_string()
        };
        assert_eq!((text("wheel"), text("axle")), ("RR".into(), "rear".into()));
        // A table from another tool with a position tirewear does not know.
        for (name, values, says) in [
            (
                "wheel",
                ["FL", "FR", "LF"],
                "row 2: unknown wheel position 'LF'",
            ),
            (
                "axle",
                ["front", "middle", "rear"],
                "row 1: unknown axle 'middle'",
            ),
        ] {
            let col: ArrayRef = Arc::new(StringArray::from(values.to_vec()));
            let field = Field::new(name, DataType::Utf8, false);
            write_batch(&path, &with_column(&rows, name, field, col)).unwrap();
            let err = read_parquet(&path).unwrap_err().to_string();
            assert!(
                err.contains("k.parquet") && err.contains(&format!("column '{name}', {says}")),
                "{err}"
            );
        }
    }

    #[test]
    fn nulls_text_in_numbers_and_other_units_are_named_not_read_as_zero() {
        let rows = vec![
            KpiRow {
                run: "R1".into(),
                friction_energy_j: 5.0,
                ..Default::default()
            };
            3
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("k.parquet");
        let text = Field::new("friction_energy_j", DataType::Utf8, true);
        let cases: [(ArrayRef, Field, &str); 3] = [
            (
                Arc::new(StringArray::from(vec!["1.5", "abc", "2"])),
                text.clone(),
                "row 1",
            ),
            (
                Arc::new(Float64Array::from(vec![Some(1.0), Some(2.0), None])),
                Field::new("friction_energy_j", DataType::Float64, true),
                "row 2",
            ),
            (
                Arc::new(Float64Array::from(vec![1.0, 2.0, 3.0])),
                Field::new("friction_energy_j", DataType::Float64, false).with_metadata(
                    std::collections::HashMap::from([("unit".to_string(), "kJ".to_string())]),
                ),
                "unit is 'kJ'",
            ),
        ];
        for (col, field, says) in cases {
            write_batch(&path, &with_column(&rows, "friction_energy_j", field, col)).unwrap();
            let err = read_parquet(&path).unwrap_err().to_string();
            assert!(
                err.contains("k.parquet")
                    && err.contains("friction_energy_j")
                    && err.contains(says),
                "{err}"
            );
        }
        // Text that converts is read as its number.
        write_batch(
            &path,
            &with_column(
                &rows,
                "friction_energy_j",
                text,
                Arc::new(StringArray::from(vec!["1.5", "7", "2"])),
            ),
        )
        .unwrap();
        assert_eq!(read_parquet(&path).unwrap()[1].friction_energy_j, 7.0);
    }
}
