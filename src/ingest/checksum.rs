//! A checksum over the data of the Parquet files tirewear writes.
//!
//! Parquet allows a CRC per page, but the Rust writer does not write them,
//! so a bit flipped inside a data page of a KPI table or a side table would
//! be read as a valid number. Each file tirewear writes therefore carries,
//! in its footer's key-value metadata under [`CHECKSUM_KEY`], the CRC-32
//! (IEEE, as zlib and `crc32fast`) of its first bytes — everything before
//! the page indexes and the footer: the magic and every row group's pages —
//! written as `"<byte count> <crc as 8 hex digits>"`. Readers check it when
//! it is present; files from other tools or from before it have none and
//! are read as before (docs/formats.md, "Checksum of tirewear's Parquet
//! files").
//!
//! Every Parquet file read, tirewear's or another tool's, also has its
//! footer's byte ranges checked against the file ([`layout_fault`]): the
//! Parquet reader panics on some damaged footers instead of returning an
//! error.

use std::io::{Read, Write};
use std::path::Path;

use parquet::arrow::arrow_reader::{ParquetRecordBatchReader, ParquetRecordBatchReaderBuilder};
use parquet::file::metadata::{KeyValue, ParquetMetaData};
use parquet::file::writer::SerializedFileWriter;

/// Footer key-value key holding the data checksum.
pub(crate) const CHECKSUM_KEY: &str = "tirewear.data_crc32";

/// A writer that counts and checksums every byte it passes on.
pub(crate) struct CrcWriter<W> {
    inner: W,
    crc: crc32fast::Hasher,
    bytes: u64,
}

impl<W: Write> CrcWriter<W> {
    pub(crate) fn new(inner: W) -> Self {
        Self {
            inner,
            crc: crc32fast::Hasher::new(),
            bytes: 0,
        }
    }
}

impl<W: Write> Write for CrcWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl<W> CrcWriter<W> {
    /// The footer entry recording what has passed so far.
    fn entry(&self) -> KeyValue {
        let value = format!("{} {:08x}", self.bytes, self.crc.clone().finalize());
        KeyValue::new(CHECKSUM_KEY.to_string(), value)
    }
}

/// Records the checksum of everything written so far (every row group) in
/// the footer that `close` writes next. Call it after the last row group.
pub(crate) fn seal<W: Write + Send>(
    writer: &mut SerializedFileWriter<CrcWriter<W>>,
) -> std::io::Result<()> {
    // The file writer buffers: push its bytes through the checksum first.
    writer.flush()?;
    let entry = writer.inner().entry();
    writer.append_key_value_metadata(entry);
    Ok(())
}

/// [`seal`] for a writer that makes its own row groups: flushes the rows
/// it still holds as a row group first.
pub(crate) fn seal_arrow<W: Write + Send>(
    writer: &mut parquet::arrow::ArrowWriter<CrcWriter<W>>,
) -> parquet::errors::Result<()> {
    writer.flush()?;
    writer.sync()?;
    let entry = writer.inner().entry();
    writer.append_key_value_metadata(entry);
    Ok(())
}

/// Why a file's data does not match the checksum its footer records, or
/// `None` when it matches or the footer records none.
#[cfg(test)]
pub(crate) fn mismatch(path: &Path, metadata: &ParquetMetaData) -> Option<String> {
    mismatch_in(path, None, metadata)
}

/// [`mismatch`] of the file `path`, read again unless `data` holds it.
pub(crate) fn mismatch_in(
    path: &Path,
    data: Option<&[u8]>,
    metadata: &ParquetMetaData,
) -> Option<String> {
    let recorded = metadata
        .file_metadata()
        .key_value_metadata()?
        .iter()
        .find(|kv| kv.key == CHECKSUM_KEY)?
        .value
        .clone();
    let Some((bytes, crc)) = recorded.as_deref().and_then(parse) else {
        return Some(format!(
            "footer key {CHECKSUM_KEY} is {recorded:?}, not \"<bytes> <8 hex digits>\""
        ));
    };
    let found = match data {
        Some(data) => Ok(usize::try_from(bytes)
            .ok()
            .and_then(|n| data.get(..n))
            .map(crc32fast::hash)),
        None => crc_of_prefix(path, bytes),
    };
    match found {
        Ok(Some(found)) if found == crc => None,
        Ok(Some(found)) => Some(format!(
            "bytes 0..{bytes} have CRC-32 {found:08x} where the footer recorded {crc:08x}: \
             the file was damaged after it was written; make it again"
        )),
        Ok(None) => Some(format!(
            "the footer's checksum covers {bytes} bytes, more than the file holds: \
             the file was cut or damaged after it was written; make it again"
        )),
        Err(e) => Some(format!("cannot be read to check its checksum: {e}")),
    }
}

fn parse(value: &str) -> Option<(u64, u32)> {
    let (bytes, crc) = value.split_once(' ')?;
    if crc.len() != 8 {
        return None;
    }
    Some((bytes.parse().ok()?, u32::from_str_radix(crc, 16).ok()?))
}

/// CRC-32 of the first `bytes` bytes of the file, `None` if it is shorter.
fn crc_of_prefix(path: &Path, bytes: u64) -> std::io::Result<Option<u32>> {
    let file = std::fs::File::open(path)?.take(bytes);
    // Parts are tens of KiB, side tables up to some MB: a buffer to fit.
    let mut reader = std::io::BufReader::with_capacity(bytes.clamp(1, 1 << 20) as usize, file);
    let mut crc = CrcWriter::new(std::io::sink());
    let seen = std::io::copy(&mut reader, &mut crc)?;
    Ok((seen == bytes).then(|| crc.crc.finalize()))
}

/// Why the footer's byte ranges cannot be the file's, or `None`: a column
/// chunk that starts before the file or runs past its end. arrow-rs asserts
/// on a negative offset or length (`ColumnChunkMetaData::byte_range`)
/// instead of returning an error, so a damaged footer is refused here
/// first, naming the row group and column.
pub(crate) fn layout_fault(metadata: &ParquetMetaData, file_len: u64) -> Option<String> {
    for (r, group) in metadata.row_groups().iter().enumerate() {
        for (c, col) in group.columns().iter().enumerate() {
            let data = col.data_page_offset();
            let start = col.dictionary_page_offset().unwrap_or(data);
            let len = col.compressed_size();
            let inside = data >= 0
                && start >= 0
                && len >= 0
                && start
                    .checked_add(len)
                    .is_some_and(|end| end as u64 <= file_len);
            if !inside {
                return Some(format!(
                    "row group {r}, column {c} ({}): bytes {start}..{start}+{len} \
                     (data pages at {data}) lie outside the file's {file_len} bytes: \
                     the file is damaged",
                    col.column_path().string()
                ));
            }
        }
    }
    None
}

/// The last field of the JSON files tirewear writes and reads back (model
/// files, `gap.json`, `kpis.report.json`, `dataset.json`, `summary.json`):
/// the CRC-32 of
/// the file's text without it (docs/formats.md, "Checksum of tirewear's
/// JSON files"). A digit changed in a number is valid JSON; the checksum
/// tells it from what tirewear wrote.
pub(crate) const JSON_CHECKSUM_FIELD: &str = "data_crc32";

/// `body`, an object as `serde_json`'s pretty printer writes it, with
/// [`JSON_CHECKSUM_FIELD`] added as its last field: the CRC-32 of `body`.
pub(crate) fn seal_json(body: &str) -> String {
    let crc = crc32fast::hash(body.as_bytes());
    let open = body
        .strip_suffix("\n}")
        .expect("a pretty JSON object ends with \\n}");
    format!("{open},\n  \"{JSON_CHECKSUM_FIELD}\": \"{crc:08x}\"\n}}\n")
}

/// Why a JSON file's text does not match its [`JSON_CHECKSUM_FIELD`], or
/// `None` when it matches or has none (files from before it, or with it
/// deleted by someone who edited the file on purpose). `head` is the text
/// parsed; `writer` names the command that wrote it, for the message.
pub(crate) fn json_mismatch(text: &str, head: &serde_json::Value, writer: &str) -> Option<String> {
    let recorded = head.get(JSON_CHECKSUM_FIELD)?;
    let edited = format!(
        "the file was damaged or edited after `{writer}` wrote it \
         (if you edited it on purpose, delete the field)"
    );
    let Some(recorded) = recorded
        .as_str()
        .filter(|s| s.len() == 8)
        .and_then(|s| u32::from_str_radix(s, 16).ok())
    else {
        return Some(format!(
            "{JSON_CHECKSUM_FIELD} is {recorded}, not 8 hex digits: {edited}"
        ));
    };
    let field = format!(",\n  \"{JSON_CHECKSUM_FIELD}\": \"{recorded:08x}\"\n}}");
    // A checkout that turned the line ends into CRLF (git's autocrlf) is
    // the same file: the JSON tirewear writes has no other carriage return.
    let text = text.replace("\r\n", "\n");
    let Some(open) = text.trim_end().strip_suffix(field.as_str()) else {
        return Some(format!(
            "{JSON_CHECKSUM_FIELD} is not the file's last field as written: {edited}"
        ));
    };
    let found = crc32fast::hash(format!("{open}\n}}").as_bytes());
    (found != recorded).then(|| {
        format!(
            "{JSON_CHECKSUM_FIELD}: the text has CRC-32 {found:08x} where the field \
             records {recorded:08x}: {edited}"
        )
    })
}

/// Files up to this size are read whole before they are parsed
/// ([`ParquetSource`]).
const IN_MEMORY_MAX: u64 = 64 << 20;

/// A Parquet file's bytes for the reader: in memory when the file is at
/// most [`IN_MEMORY_MAX`], else the open file.
///
/// The Parquet reader's `File` source clones the descriptor and seeks for
/// each column chunk it reads, and asks the file's size each time: some
/// 190 system calls for one run's three parts, which a night's commit
/// makes for every run (docs/nightly.md, "Many runs"). Read whole, a file
/// costs one read, and its checksum is taken over the same bytes.
pub(crate) enum ParquetSource {
    Memory(bytes::Bytes),
    File(std::fs::File),
}

impl ParquetSource {
    /// `path`'s bytes, or the open file when it is larger than
    /// [`IN_MEMORY_MAX`]; an error for what is not a regular file
    /// (`/dev/zero` has no end, a FIFO's open waits for a writer).
    pub(crate) fn open(path: &Path) -> crate::ingest::Result<ParquetSource> {
        let (file, meta) = crate::ingest::open_regular(path)?;
        if meta.len() > IN_MEMORY_MAX {
            return Ok(ParquetSource::File(file));
        }
        // At most the size just read: a file still being written is not
        // followed past it.
        let mut data = Vec::with_capacity(meta.len() as usize);
        file.take(meta.len())
            .read_to_end(&mut data)
            .map_err(|e| crate::ingest::IngestError::io(path, e))?;
        Ok(ParquetSource::Memory(data.into()))
    }
}

impl parquet::file::reader::Length for ParquetSource {
    fn len(&self) -> u64 {
        match self {
            ParquetSource::Memory(data) => data.len() as u64,
            ParquetSource::File(file) => file.len(),
        }
    }
}

impl parquet::file::reader::ChunkReader for ParquetSource {
    type T = SourceRead;

    fn get_read(&self, start: u64) -> parquet::errors::Result<SourceRead> {
        Ok(match self {
            ParquetSource::Memory(data) => SourceRead::Memory(data.get_read(start)?),
            ParquetSource::File(file) => SourceRead::File(file.get_read(start)?),
        })
    }

    fn get_bytes(&self, start: u64, length: usize) -> parquet::errors::Result<bytes::Bytes> {
        match self {
            ParquetSource::Memory(data) => data.get_bytes(start, length),
            ParquetSource::File(file) => file.get_bytes(start, length),
        }
    }
}

/// A reader from a [`ParquetSource`].
pub(crate) enum SourceRead {
    Memory(bytes::buf::Reader<bytes::Bytes>),
    File(std::io::BufReader<std::fs::File>),
}

impl Read for SourceRead {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            SourceRead::Memory(r) => r.read(buf),
            SourceRead::File(r) => r.read(buf),
        }
    }
}

/// Every Parquet file starts and ends with these four bytes.
const PARQUET_MAGIC: &[u8; 4] = b"PAR1";

/// Bytes of a file's start [`not_parquet`] reads to say what it is.
const HEAD_BYTES: u64 = 512;

/// Why `source` cannot be a Parquet file, from its first and last bytes,
/// in words a user can act on; None where it may be one (or cannot be
/// read: the Parquet reader then names the fault). Of a CSV file, an MCAP
/// file or a file cut short, the Parquet reader says only "Corrupt footer".
pub(crate) fn not_parquet<R: parquet::file::reader::ChunkReader>(source: &R) -> Option<String> {
    let len = source.len();
    let head = source.get_bytes(0, len.min(HEAD_BYTES) as usize).ok()?;
    let tail = match len.checked_sub(4) {
        Some(at) => source.get_bytes(at, 4).ok()?,
        None => bytes::Bytes::new(),
    };
    why_not_parquet(&head, &tail, len)
}

/// [`not_parquet`] on the bytes read: the file's first (up to
/// [`HEAD_BYTES`]) and last four, and its length.
fn why_not_parquet(head: &[u8], tail: &[u8], len: u64) -> Option<String> {
    // The smallest Parquet file: the magic, a footer length, the magic.
    const SMALLEST: u64 = 12;
    let starts = head.starts_with(PARQUET_MAGIC);
    if starts && tail == PARQUET_MAGIC && len >= SMALLEST {
        return None;
    }
    if starts {
        return Some(format!(
            "starts as a Parquet file (`PAR1`) but has no footer (it does not end with \
             `PAR1`; {len} bytes): cut short, or still being written"
        ));
    }
    if len == 0 {
        return Some("is empty (0 bytes), not a Parquet file".to_string());
    }
    Some(format!(
        "is not a Parquet file (one starts and ends with `PAR1`): {}",
        what_it_is(head)
    ))
}

/// What a file's first bytes show it to be ("it is an MCAP file"), for
/// [`why_not_parquet`] and a destination the report would replace.
pub(crate) fn what_it_is(head: &[u8]) -> String {
    const KNOWN: [(&[u8], &str); 7] = [
        (b"\x89MCAP", "an MCAP file"),
        (PARQUET_MAGIC, "a Parquet file"),
        (&[0x28, 0xb5, 0x2f, 0xfd], "zstd-compressed data"),
        (&[0x1f, 0x8b], "gzip-compressed data"),
        (b"PK\x03\x04", "a ZIP archive (an .xlsx workbook is one)"),
        (b"ARROW1", "an Arrow IPC file"),
        (b"ORC", "an ORC file"),
    ];
    if let Some((_, name)) = KNOWN.iter().find(|(magic, _)| head.starts_with(magic)) {
        return format!("it is {name}");
    }
    if let Some(line) = first_line_of_text(head) {
        return format!("it is text, beginning `{line}`");
    }
    let bytes: Vec<String> = head.iter().take(4).map(|b| format!("{b:02x}")).collect();
    format!("it starts with the bytes {}", bytes.join(" "))
}

/// The first line (at most 60 characters) where `head` is text: UTF-8,
/// perhaps cut inside a character at its end, with no control characters
/// but tabs and line ends.
fn first_line_of_text(head: &[u8]) -> Option<String> {
    const SHOWN: usize = 60;
    let text = match std::str::from_utf8(head) {
        Ok(text) => text,
        Err(e) if e.error_len().is_none() => std::str::from_utf8(&head[..e.valid_up_to()]).ok()?,
        Err(_) => return None,
    };
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if text
        .chars()
        .any(|c| c.is_control() && !matches!(c, '\t' | '\n' | '\r'))
    {
        return None;
    }
    let line = text.lines().next().unwrap_or_default();
    let shown: String = line.chars().take(SHOWN).collect();
    Some(if shown.len() < line.len() {
        format!("{shown}…")
    } else {
        shown
    })
}

/// A Parquet file opened for reading, its footer read and its byte ranges
/// checked against the file (any file) and its data against the footer's
/// checksum (tirewear's files); every error names the file.
pub(crate) fn open_parquet(path: &Path) -> crate::ingest::Result<OpenedParquet> {
    use crate::ingest::IngestError;
    use parquet::file::reader::Length;
    let source = ParquetSource::open(path)?;
    if let Some(why) = not_parquet(&source) {
        return Err(IngestError::invalid(path, "file", why));
    }
    let file_len = source.len();
    let data = match &source {
        ParquetSource::Memory(data) => Some(data.clone()),
        ParquetSource::File(_) => None,
    };
    let builder = ParquetRecordBatchReaderBuilder::try_new(source).map_err(|source| {
        IngestError::Parquet {
            path: path.to_path_buf(),
            source,
        }
    })?;
    if let Some(why) = layout_fault(builder.metadata(), file_len) {
        return Err(IngestError::invalid(path, "footer", why));
    }
    match mismatch_in(path, data.as_deref(), builder.metadata()) {
        None => Ok(OpenedParquet(builder)),
        Some(why) => Err(IngestError::invalid(path, "data checksum", why)),
    }
}

/// The record batches of an opened Parquet file, each read with the
/// decoder's panics caught: the Parquet reader asserts on some damaged data
/// pages (a run-length header longer than ten bytes panics `get_vlq_int`,
/// in release builds too), which a file without tirewear's checksum (another
/// tool's) can carry. Such a panic is the file's error, and no batch
/// follows it.
pub(crate) struct Batches(Option<ParquetRecordBatchReader>);

/// A Parquet file [`open_parquet`] opened and checked. Its batches are read
/// only as [`Batches`], so no reader of a Parquet file can meet the
/// decoder's panics unguarded.
pub(crate) struct OpenedParquet(ParquetRecordBatchReaderBuilder<ParquetSource>);

impl OpenedParquet {
    /// The file's Arrow schema (its key-value metadata included).
    pub(crate) fn schema(&self) -> &arrow_schema::SchemaRef {
        self.0.schema()
    }

    /// The file's record batches, each read with the decoder's panics caught.
    pub(crate) fn batches(self) -> Result<Batches, parquet::errors::ParquetError> {
        Ok(Batches(Some(self.0.build()?)))
    }
}

impl Iterator for Batches {
    type Item = Result<arrow_array::RecordBatch, arrow_schema::ArrowError>;

    fn next(&mut self) -> Option<Self::Item> {
        let reader = self.0.as_mut()?;
        match crate::guard::catch_panic(|| reader.next()) {
            Ok(batch) => batch,
            Err(msg) => {
                // The reader is mid-page: it is dropped, not read on.
                self.0 = None;
                Some(Err(arrow_schema::ArrowError::ParseError(format!(
                    "damaged data: the Parquet decoder stopped on it ({msg})"
                ))))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorded_value_parses_only_in_its_own_form() {
        assert_eq!(parse("1234 0000abcd"), Some((1234, 0xabcd)));
        assert_eq!(parse("1234 abcd"), None);
        assert_eq!(parse("x 0000abcd"), None);
        assert_eq!(parse("1234"), None);
        assert_eq!(parse("1234 0000abcg"), None);
    }

    /// Every byte of a small table's checksummed data changed in turn is
    /// reported; the undamaged file and a file without the key are not.
    #[test]
    fn every_changed_byte_of_the_data_is_a_mismatch() {
        use arrow_array::{Float64Array, RecordBatch};
        use parquet::file::metadata::ParquetMetaDataReader;
        use std::sync::Arc;
        let values = Float64Array::from_iter_values((0..40).map(|i| i as f64 * 1.25));
        let batch = RecordBatch::try_from_iter([("energy_j", Arc::new(values) as _)]).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let mut clean = Vec::new();
        crate::kpi::table::write_batch_to(&mut clean, &batch).unwrap();
        std::fs::write(&path, &clean).unwrap();
        let footer = |p: &Path| {
            ParquetMetaDataReader::new()
                .parse_and_finish(&std::fs::File::open(p).unwrap())
                .unwrap()
        };
        let meta = footer(&path);
        assert_eq!(mismatch(&path, &meta), None);
        assert_eq!(mismatch_in(&path, Some(&clean), &meta), None);
        let value = meta
            .file_metadata()
            .key_value_metadata()
            .and_then(|kv| kv.iter().find(|kv| kv.key == CHECKSUM_KEY)?.value.clone())
            .unwrap();
        let (covered, _) = parse(&value).unwrap();
        assert!(covered > 100 && (covered as usize) < clean.len());
        for at in 0..covered as usize {
            let mut bytes = clean.clone();
            bytes[at] ^= 0x80 >> (at % 8);
            std::fs::write(&path, &bytes).unwrap();
            let why = mismatch(&path, &meta).unwrap_or_else(|| panic!("byte {at}"));
            assert!(why.contains("damaged after it was written"), "{why}");
            // The bytes in memory (`open_parquet`'s route) say the same.
            assert_eq!(mismatch_in(&path, Some(&bytes), &meta), Some(why));
        }
        // Cut inside the data: the file holds fewer bytes than recorded.
        let cut = &clean[..covered as usize - 1];
        std::fs::write(&path, cut).unwrap();
        let why = mismatch(&path, &meta).unwrap();
        assert!(why.contains("more than the file holds"), "{why}");
        assert_eq!(mismatch_in(&path, Some(cut), &meta), Some(why));
        // A footer without the key (another writer): nothing to check.
        let mut plain = Vec::new();
        let mut w = parquet::arrow::ArrowWriter::try_new(&mut plain, batch.schema(), None).unwrap();
        w.write(&batch).unwrap();
        w.close().unwrap();
        let other = dir.path().join("other.parquet");
        std::fs::write(&other, plain).unwrap();
        assert_eq!(mismatch(&other, &footer(&other)), None);
    }

    #[test]
    fn a_file_read_whole_or_through_its_descriptor_reads_the_same() {
        // `open_parquet` reads files up to IN_MEMORY_MAX whole; larger ones
        // through the Parquet reader's `File` source. Both sources must
        // give the same batches of the same file.
        use arrow_array::{Float64Array, RecordBatch, StringArray};
        use std::sync::Arc;
        let n = 5_000;
        let batch = RecordBatch::try_from_iter([
            (
                "run",
                Arc::new(StringArray::from_iter_values(
                    (0..n).map(|i| format!("r{}", i / 7)),
                )) as _,
            ),
            (
                "energy_j",
                Arc::new(Float64Array::from_iter_values(
                    (0..n).map(|i| i as f64 * 0.5),
                )) as _,
            ),
        ])
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let mut bytes = Vec::new();
        crate::kpi::table::write_part_to(&mut bytes, &batch).unwrap();
        std::fs::write(&path, &bytes).unwrap();
        let opened = open_parquet(&path).unwrap();
        let in_memory: Vec<RecordBatch> = opened.batches().unwrap().map(|b| b.unwrap()).collect();
        let file = ParquetSource::File(std::fs::File::open(&path).unwrap());
        let through_file: Vec<RecordBatch> = ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap()
            .build()
            .unwrap()
            .map(|b| b.unwrap())
            .collect();
        // (The footer's key-value metadata comes back as the schema's.)
        assert_eq!(in_memory, through_file);
        let read =
            arrow_select::concat::concat_batches(&in_memory[0].schema(), &in_memory).unwrap();
        assert_eq!(read.columns(), batch.columns());
        assert!(matches!(
            ParquetSource::open(&path).unwrap(),
            ParquetSource::Memory(data) if data.as_ref() == bytes.as_slice()
        ));
        // Neither a device (`/dev/zero` has no end) nor a FIFO (whose open
        // waits for a writer: this test would hang) is opened.
        #[cfg(unix)]
        {
            let fifo = dir.path().join("fifo.parquet");
            crate::make_fifo(&fifo);
            for path in [Path::new("/dev/zero"), fifo.as_path(), dir.path()] {
                let e = open_parquet(path).err().expect("refused").to_string();
                assert!(
                    e.contains(&path.display().to_string()) && e.contains("not a regular file"),
                    "{e}"
                );
            }
        }
    }

    /// What a file that is not Parquet is said to be, case by case by hand;
    /// a written table passes, and cut anywhere it is refused.
    #[test]
    fn files_that_are_not_parquet_are_named_for_what_they_are() {
        let say = |bytes: &[u8]| not_parquet(&bytes::Bytes::copy_from_slice(bytes));
        let csv = b"event,track,car\nE01,valle-rossa,car1\n";
        assert_eq!(
            say(csv).unwrap(),
            "is not a Parquet file (one starts and ends with `PAR1`): \
             it is text, beginning `event,track,car`"
        );
        // A byte-order mark is skipped; a long line is cut at 60 characters
        // (these are two bytes each: the cut counts characters).
        let long = format!("\u{feff}{}", "é".repeat(300));
        let said = say(long.as_bytes()).unwrap();
        assert!(
            said.ends_with(&format!("beginning `{}…`", "é".repeat(60))),
            "{said}"
        );
        // 512 bytes of text cut inside a character are still text.
        let cut_char = &"é".repeat(300).into_bytes()[..HEAD_BYTES as usize - 1];
        assert!(say(cut_char).unwrap().contains("it is text"));
        assert!(
            say(b"\x89MCAP0\r\n....")
                .unwrap()
                .ends_with("it is an MCAP file")
        );
        assert!(
            say(&[0x28, 0xb5, 0x2f, 0xfd, 0, 1])
                .unwrap()
                .ends_with("zstd-compressed data")
        );
        assert!(say(b"PK\x03\x04rest").unwrap().contains("ZIP archive"));
        assert!(
            say(&[0x10, 0x00, 0xff, 0x7f, 0x01])
                .unwrap()
                .ends_with("it starts with the bytes 10 00 ff 7f")
        );
        assert_eq!(say(b"").unwrap(), "is empty (0 bytes), not a Parquet file");
        // PAR1 at both ends but shorter than the smallest Parquet file.
        assert!(say(b"PAR1PAR1").unwrap().contains("has no footer"));

        let values = arrow_array::Float64Array::from_iter_values((0..40).map(f64::from));
        let batch = arrow_array::RecordBatch::try_from_iter([(
            "energy_j",
            std::sync::Arc::new(values) as arrow_array::ArrayRef,
        )])
        .unwrap();
        let mut table = Vec::new();
        crate::kpi::table::write_batch_to(&mut table, &batch).unwrap();
        assert_eq!(say(&table), None);
        for cut in 1..table.len() {
            let said = say(&table[..cut]).expect("a cut table is refused");
            if cut >= 4 {
                assert!(said.contains("cut short") && said.contains(&format!("{cut} bytes")));
            }
        }
    }

    #[test]
    fn the_writer_checksums_what_it_passes_on() {
        // zlib's CRC-32 of "123456789" is cbf43926 (the standard check value).
        let mut w = CrcWriter::new(Vec::new());
        w.write_all(b"12345").unwrap();
        w.write_all(b"6789").unwrap();
        assert_eq!(w.bytes, 9);
        assert_eq!(w.crc.clone().finalize(), 0xcbf4_3926);
        assert_eq!(w.inner, b"123456789");
    }

    /// A column chunk's range outside the file (a negative offset or size,
    /// one that overflows or ends past the file) is a fault naming the row
    /// group and column; the undamaged footer is not. The Parquet reader
    /// panicked on the negative ones (found by the robustness suite).
    #[test]
    fn column_ranges_outside_the_file_are_faults() {
        use arrow_array::{Float64Array, RecordBatch};
        use parquet::file::metadata::{ColumnChunkMetaDataBuilder, ParquetMetaDataReader};
        use std::sync::Arc;
        let values = Float64Array::from_iter_values((0..40).map(f64::from));
        let batch = RecordBatch::try_from_iter([("energy_j", Arc::new(values) as _)]).unwrap();
        let mut bytes = Vec::new();
        crate::kpi::table::write_batch_to(&mut bytes, &batch).unwrap();
        let file = tempfile::tempfile().unwrap();
        std::io::Write::write_all(&mut &file, &bytes).unwrap();
        let meta = ParquetMetaDataReader::new()
            .parse_and_finish(&file)
            .unwrap();
        let len = bytes.len() as u64;
        assert_eq!(layout_fault(&meta, len), None);
        let col = meta.row_group(0).column(0);
        let end = (col
            .dictionary_page_offset()
            .unwrap_or(col.data_page_offset())
            + col.compressed_size()) as u64;
        assert_eq!(layout_fault(&meta, end), None);
        assert!(layout_fault(&meta, end - 1).is_some(), "ends past the file");
        type Edit = fn(ColumnChunkMetaDataBuilder) -> ColumnChunkMetaDataBuilder;
        let edits: [(&str, Edit); 4] = [
            ("negative data offset", |b| {
                b.set_data_page_offset(-4).set_dictionary_page_offset(None)
            }),
            ("negative dictionary offset", |b| {
                b.set_dictionary_page_offset(Some(-1))
            }),
            ("negative size", |b| b.set_total_compressed_size(-100)),
            ("size that overflows", |b| {
                b.set_total_compressed_size(i64::MAX)
            }),
        ];
        for (what, edit) in edits {
            let column = edit(meta.row_group(0).column(0).clone().into_builder())
                .build()
                .unwrap();
            let group = meta
                .row_group(0)
                .clone()
                .into_builder()
                .set_column_metadata(vec![column])
                .build()
                .unwrap();
            let damaged = meta
                .clone()
                .into_builder()
                .set_row_groups(vec![group])
                .build();
            let why = layout_fault(&damaged, len).unwrap_or_else(|| panic!("{what}"));
            assert!(
                why.contains("row group 0, column 0 (energy_j)"),
                "{what}: {why}"
            );
        }
    }

    /// A sealed JSON object reads back; every changed byte outside the
    /// field's own name is a mismatch; CRLF line ends and a deleted field
    /// pass; a value that is not 8 hex digits, or a field moved, does not.
    #[test]
    fn sealed_json_refuses_every_changed_byte() {
        let body = serde_json::to_string_pretty(&serde_json::json!({
            "run": "E01-valle-rossa-car1-R1",
            "rows": 4,
            "wear_pct": [12.5, 13.25],
        }))
        .unwrap();
        let sealed = seal_json(&body);
        let parse = |t: &str| serde_json::from_str::<serde_json::Value>(t);
        let head = parse(&sealed).unwrap();
        assert_eq!(
            head[JSON_CHECKSUM_FIELD],
            format!("{:08x}", crc32fast::hash(body.as_bytes()))
        );
        assert_eq!(json_mismatch(&sealed, &head, "w"), None);
        assert_eq!(json_mismatch(&body, &parse(&body).unwrap(), "w"), None);
        let crlf = sealed.replace('\n', "\r\n");
        assert_eq!(json_mismatch(&crlf, &parse(&crlf).unwrap(), "w"), None);
        let name = sealed.find(JSON_CHECKSUM_FIELD).unwrap();
        let (mut refused, mut unparsed) = (0, 0);
        for at in 0..sealed.len() {
            let mut bytes = sealed.clone().into_bytes();
            bytes[at] ^= 0x01;
            let Ok(text) = String::from_utf8(bytes) else {
                continue;
            };
            let Ok(head) = parse(&text) else {
                unparsed += 1;
                continue;
            };
            match json_mismatch(&text, &head, "tirewear w") {
                Some(why) => {
                    assert!(
                        why.contains("`tirewear w`") && why.contains("delete the field"),
                        "{why}"
                    );
                    refused += 1;
                }
                // The field's own name changed: the file has no checksum.
                None => assert!(
                    (name..name + JSON_CHECKSUM_FIELD.len()).contains(&at),
                    "byte {at}"
                ),
            }
        }
        assert!(refused > 40 && unparsed > 10, "{refused} {unparsed}");
    }
}
