//! Run telemetry in MCAP: one topic per wheel (`/tire/FL` ...) and one for
//! the vehicle (`/vehicle`), protobuf-encoded with the schemas of
//! `proto/tirewear.proto`. Two message forms: per-sample messages (Foxglove
//! plots them) and packed blocks of equally spaced samples (fast).

use super::protowire::{self, Field, Scalar};
use super::{IngestError, Result};
use crate::Wheel;
use mcap::records::MessageHeader;
use prost::Message as _;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Generated protobuf types (`tirewear.v1`).
pub mod proto {
    include!(concat!(env!("OUT_DIR"), "/tirewear.v1.rs"));
}

/// Binary `FileDescriptorSet` of `proto/tirewear.proto`, the data of every schema record.
pub(crate) const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/tirewear_fds.bin"));

pub(crate) const TIRE_SAMPLE: &str = "tirewear.v1.TireSample";
pub(crate) const TIRE_BLOCK: &str = "tirewear.v1.TireBlock";
pub(crate) const VEHICLE_SAMPLE: &str = "tirewear.v1.VehicleSample";
pub(crate) const VEHICLE_BLOCK: &str = "tirewear.v1.VehicleBlock";
pub(crate) const VEHICLE_TOPIC: &str = "/vehicle";

/// Largest MCAP record we accept (bytes): a corrupted length field becomes an
/// error instead of a huge allocation.
pub(crate) const RECORD_LENGTH_LIMIT: usize = 256 << 20;

/// Which message form a file uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// One message per sample per topic (`TireSample`, `VehicleSample`).
    Sample,
    /// Packed blocks of equally spaced samples (`TireBlock`, `VehicleBlock`).
    Block,
}

/// Declares a columnar series type with one `Vec` per channel, and the code
/// that appends a per-sample message or a packed block to it, from one list
/// of channels with their field numbers in the per-sample message (in the
/// block message each channel is field number + 2, after the start time and
/// the sample period; `proto/tirewear.proto`).
macro_rules! series {
    ($series:ident, $sample:ident, $block:ident, $elem:ident,
     [$($ch:ident: $t:ty = $num:literal),* $(,)?]) => {
        /// Columnar channels of one topic, in file order; `time_ns` is the sample time.
        #[derive(Debug, Clone, Default, PartialEq)]
        pub struct $series {
            pub time_ns: Vec<u64>,
            $(pub $ch: Vec<$t>,)*
        }

        impl $series {
            pub fn len(&self) -> usize {
                self.time_ns.len()
            }
            pub fn is_empty(&self) -> bool {
                self.time_ns.is_empty()
            }
            pub(crate) fn push_sample(&mut self, time_ns: u64, s: &proto::$sample) {
                self.time_ns.push(time_ns);
                $(self.$ch.push(s.$ch);)*
            }
            /// Appends a block, or says which channel's length disagrees.
            pub(crate) fn push_block(&mut self, b: &proto::$block) -> std::result::Result<(), String> {
                let n = b.$elem.len();
                $(if b.$ch.len() != n {
                    return Err(format!(
                        "channel {} has {} samples, {} has {n}",
                        stringify!($ch), b.$ch.len(), stringify!($elem)
                    ));
                })*
                check_block_times(n, b.start_time_ns, b.sample_period_ns)?;
                self.time_ns.extend((0..n as u64).map(|i| b.start_time_ns + i * b.sample_period_ns));
                $(self.$ch.extend_from_slice(&b.$ch);)*
                Ok(())
            }
            /// [`Self::push_sample`] straight from the message's bytes;
            /// false (and nothing appended) where they use anything the
            /// fast reader does not (`protowire`).
            fn push_sample_bytes(&mut self, time_ns: u64, mut data: &[u8]) -> bool {
                $(let mut $ch = <$t>::default();)*
                while let Some((&key, rest)) = data.split_first() {
                    // Every field is a fixed-width number below 16: a
                    // one-byte key, then the value.
                    let read = $(if u32::from(key) == ($num << 3) | <$t as Scalar>::WIRE {
                        <$t as Scalar>::read_fixed(rest).map(|(v, rest)| {
                            $ch = v;
                            rest
                        })
                    } else)* {
                        None
                    };
                    match read {
                        Some(rest) => data = rest,
                        None => return false,
                    }
                }
                self.time_ns.push(time_ns);
                $(self.$ch.push($ch);)*
                true
            }
            /// [`Self::push_block`] straight from the message's bytes, the
            /// packed arrays copied from them; `None` (and nothing appended)
            /// where they use anything the fast reader does not (`protowire`).
            fn push_block_bytes(&mut self, mut data: &[u8]) -> Option<std::result::Result<(), String>> {
                let (mut start, mut period) = (0u64, 0u64);
                $(let mut $ch: Option<&[u8]> = None;)*
                while !data.is_empty() {
                    match protowire::next_field(&mut data)? {
                        (1, Field::Varint(v)) => start = v,
                        (2, Field::Varint(v)) => period = v,
                        $((n, Field::Bytes(b)) if n == $num + 2 && $ch.is_none() => $ch = Some(b),)*
                        _ => return None,
                    }
                }
                let n = protowire::packed_len::<f32>($elem)?;
                $(let len = protowire::packed_len::<$t>($ch)?;
                if len != n {
                    return Some(Err(format!(
                        "channel {} has {len} samples, {} has {n}",
                        stringify!($ch), stringify!($elem)
                    )));
                })*
                if let Err(e) = check_block_times(n, start, period) {
                    return Some(Err(e));
                }
                self.time_ns.extend((0..n as u64).map(|i| start + i * period));
                $(<$t as Scalar>::extend_packed(&mut self.$ch, $ch.unwrap_or_default());)*
                Some(Ok(()))
            }
            /// Room for `additional` more samples in every channel.
            fn reserve(&mut self, additional: usize) {
                self.time_ns.reserve(additional);
                $(self.$ch.reserve(additional);)*
            }
            /// Appends another series (the next part of the same topic).
            pub(crate) fn append(&mut self, mut other: Self) {
                self.time_ns.append(&mut other.time_ns);
                $(self.$ch.append(&mut other.$ch);)*
            }

            /// Sample `i` as a per-sample message.
            pub fn sample(&self, i: usize) -> proto::$sample {
                proto::$sample { $($ch: self.$ch[i],)* }
            }
        }

        impl proto::$block {
            fn push(&mut self, s: &proto::$sample) {
                $(self.$ch.push(s.$ch);)*
            }
        }
    };
}

series!(WheelSeries, TireSample, TireBlock, vx_mps, [
    vx_mps: f32 = 1, vy_mps: f32 = 2, omega_radps: f32 = 3, rolling_radius_m: f32 = 4,
    fx_n: f32 = 5, fy_n: f32 = 6, fz_n: f32 = 7, t_surface_c: f32 = 8, t_inner_c: f32 = 9,
    pressure_pa: f32 = 10, camber_deg: f32 = 11,
]);
series!(VehicleSeries, VehicleSample, VehicleBlock, speed_mps, [
    speed_mps: f32 = 1, t_track_c: f32 = 2, t_air_c: f32 = 3, distance_m: f64 = 4,
]);

impl WheelSeries {
    /// The eleven channels in field order (`proto/tirewear.proto`).
    pub fn channels(&self) -> [&[f32]; 11] {
        [
            &self.vx_mps,
            &self.vy_mps,
            &self.omega_radps,
            &self.rolling_radius_m,
            &self.fx_n,
            &self.fy_n,
            &self.fz_n,
            &self.t_surface_c,
            &self.t_inner_c,
            &self.pressure_pa,
            &self.camber_deg,
        ]
    }
}

/// A block's times must be representable: a non-zero period when it has
/// samples, and the last sample's time within u64 nanoseconds.
fn check_block_times(n: usize, start: u64, period: u64) -> std::result::Result<(), String> {
    if n > 0 && period == 0 {
        return Err("sample_period_ns is 0".into());
    }
    let last = (n as u64).checked_sub(1).map_or(Some(start), |k| {
        k.checked_mul(period).and_then(|d| d.checked_add(start))
    });
    if last.is_none() {
        return Err(format!(
            "{n} samples of {period} ns from {start} ns run past the end of time (u64 ns)"
        ));
    }
    Ok(())
}

/// Identifies a run inside its telemetry file (an MCAP metadata record named
/// `tirewear.run`; informative, readers rely on the manifest).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RunInfo {
    pub run: String,
    pub event: String,
    pub car: String,
    pub sample_rate_hz: f64,
}

/// Streams one run's telemetry into an MCAP file (zstd chunks, summary,
/// chunk and message indexes), written atomically.
pub(crate) struct TelemetryWriter {
    path: PathBuf,
    out: Option<crate::atomic::AtomicFile>,
    mcap: mcap::Writer<BufWriter<File>>,
    encoding: Encoding,
    period_ns: u64,
    block_len: usize,
    tire_channels: [u16; 4],
    vehicle_channel: u16,
    seq: u32,
    pending: Option<Pending>,
}

/// Blocks under construction (block form only).
struct Pending {
    start_ns: u64,
    n: usize,
    tires: [proto::TireBlock; 4],
    vehicle: proto::VehicleBlock,
}

impl TelemetryWriter {
    /// Creates `path`. `block_len` is the number of samples per block (block form).
    pub fn create(
        path: &Path,
        info: &RunInfo,
        encoding: Encoding,
        block_len: usize,
    ) -> Result<Self> {
        let io_err = |e| IngestError::io(path, e);
        let mc = |source| IngestError::Mcap {
            path: path.to_path_buf(),
            source,
        };
        let mut out = crate::atomic::AtomicFile::create(path).map_err(io_err)?;
        let handle = out.file().try_clone().map_err(io_err)?;
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(concat!("tirewear ", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(1 << 20));
        let mut mcap = opts
            .create(BufWriter::with_capacity(1 << 20, handle))
            .map_err(mc)?;
        let (tire_schema, veh_schema) = match encoding {
            Encoding::Sample => (TIRE_SAMPLE, VEHICLE_SAMPLE),
            Encoding::Block => (TIRE_BLOCK, VEHICLE_BLOCK),
        };
        let ts = mcap
            .add_schema(tire_schema, "protobuf", FILE_DESCRIPTOR_SET)
            .map_err(mc)?;
        let vs = mcap
            .add_schema(veh_schema, "protobuf", FILE_DESCRIPTOR_SET)
            .map_err(mc)?;
        let mut tire_channels = [0u16; 4];
        for w in Wheel::ALL {
            let meta = BTreeMap::from([("wheel".to_string(), w.name().to_string())]);
            tire_channels[w.index()] = mcap
                .add_channel(ts, w.topic(), "protobuf", &meta)
                .map_err(mc)?;
        }
        let vehicle_channel = mcap
            .add_channel(vs, VEHICLE_TOPIC, "protobuf", &BTreeMap::new())
            .map_err(mc)?;
        let metadata = BTreeMap::from([
            ("run".to_string(), info.run.clone()),
            ("event".to_string(), info.event.clone()),
            ("car".to_string(), info.car.clone()),
            (
                "sample_rate_hz".to_string(),
                info.sample_rate_hz.to_string(),
            ),
            (
                "format_version".to_string(),
                super::manifest::FORMAT_VERSION.to_string(),
            ),
        ]);
        mcap.write_metadata(&mcap::records::Metadata {
            name: "tirewear.run".into(),
            metadata,
        })
        .map_err(mc)?;
        Ok(Self {
            path: path.to_path_buf(),
            out: Some(out),
            mcap,
            encoding,
            period_ns: (1e9 / info.sample_rate_hz).round() as u64,
            block_len: block_len.max(1),
            tire_channels,
            vehicle_channel,
            seq: 0,
            pending: None,
        })
    }

    /// Adds an MCAP metadata record (the importer's source file, channel
    /// map and list of estimated channels).
    pub(crate) fn write_metadata(
        &mut self,
        name: &str,
        metadata: BTreeMap<String, String>,
    ) -> Result<()> {
        self.mcap
            .write_metadata(&mcap::records::Metadata {
                name: name.into(),
                metadata,
            })
            .map_err(|e| self.mcap_err(e))
    }

    fn mcap_err(&self, source: mcap::McapError) -> IngestError {
        IngestError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    fn write_msg(&mut self, channel_id: u16, time_ns: u64, data: &[u8]) -> Result<()> {
        self.seq = self.seq.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.seq,
            log_time: time_ns,
            publish_time: time_ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_err(e))
    }

    /// Appends one time step. Steps must come in increasing time; a step that
    /// does not follow the previous one by exactly one sample period (a
    /// dropout) starts a new block.
    pub fn push(
        &mut self,
        time_ns: u64,
        tires: &[proto::TireSample; 4],
        vehicle: &proto::VehicleSample,
    ) -> Result<()> {
        match self.encoding {
            Encoding::Sample => {
                let mut buf = Vec::with_capacity(64);
                for w in Wheel::ALL {
                    buf.clear();
                    tires[w.index()].encode(&mut buf).expect("Vec grows");
                    self.write_msg(self.tire_channels[w.index()], time_ns, &buf)?;
                }
                buf.clear();
                vehicle.encode(&mut buf).expect("Vec grows");
                self.write_msg(self.vehicle_channel, time_ns, &buf)
            }
            Encoding::Block => {
                let contiguous = matches!(&self.pending,
                    Some(p) if p.n < self.block_len && time_ns == p.start_ns + p.n as u64 * self.period_ns);
                if !contiguous {
                    self.flush_block()?;
                    let mut p = Pending {
                        start_ns: time_ns,
                        n: 0,
                        tires: Default::default(),
                        vehicle: Default::default(),
                    };
                    for b in &mut p.tires {
                        b.start_time_ns = time_ns;
                        b.sample_period_ns = self.period_ns;
                    }
                    p.vehicle.start_time_ns = time_ns;
                    p.vehicle.sample_period_ns = self.period_ns;
                    self.pending = Some(p);
                }
                let p = self.pending.as_mut().expect("set above");
                for (b, s) in p.tires.iter_mut().zip(tires) {
                    b.push(s);
                }
                p.vehicle.push(vehicle);
                p.n += 1;
                Ok(())
            }
        }
    }

    fn flush_block(&mut self) -> Result<()> {
        let Some(p) = self.pending.take() else {
            return Ok(());
        };
        for w in Wheel::ALL {
            let data = p.tires[w.index()].encode_to_vec();
            self.write_msg(self.tire_channels[w.index()], p.start_ns, &data)?;
        }
        let data = p.vehicle.encode_to_vec();
        self.write_msg(self.vehicle_channel, p.start_ns, &data)
    }

    /// Writes the summary and indexes and moves the file into place.
    pub fn finish(mut self) -> Result<()> {
        self.flush_block()?;
        self.mcap.finish().map_err(|e| self.mcap_err(e))?;
        let Self {
            path, out, mcap, ..
        } = self;
        let io_err = |e| IngestError::io(&path, e);
        mcap.into_inner()
            .into_inner()
            .map_err(|e| io_err(e.into_error()))?;
        out.expect("set in create").commit().map_err(io_err)
    }
}

/// Name of the metadata record `tirewear import` writes.
pub const IMPORT_METADATA: &str = "tirewear.import";

/// All channels of one run, as read from its MCAP file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunTelemetry {
    /// Indexed by [`Wheel::index`].
    pub wheels: [WheelSeries; 4],
    pub vehicle: VehicleSeries,
    /// Message form found in the file (`None` if it held no tirewear topic).
    pub encoding: Option<Encoding>,
    /// Messages on topics this reader does not know (ignored).
    pub ignored_messages: u64,
    /// Channels `tirewear import` estimated rather than measured (the
    /// `estimated` entry of the `tirewear.import` metadata record, found
    /// through the summary's metadata index); `None` for a measured run.
    pub estimated: Option<String>,
}

/// Reads a telemetry MCAP file (either message form, chunked or not,
/// compressed or not). Files with a summary and chunk indexes are decoded
/// chunk by chunk in parallel (rayon) from a memory map; others are read
/// linearly. Damage (truncation, a bad length, a message that does not
/// decode) is an error naming the file and the message.
pub fn read_telemetry(path: &Path) -> Result<RunTelemetry> {
    let run = match read_indexed(path)? {
        Some(run) => run,
        None => read_telemetry_linear(path)?,
    };
    check_spans(path, &run)?;
    Ok(run)
}

/// How far the topics' time spans may disagree: 1 s, or 2 % of the run.
const SPAN_TOLERANCE: (f64, f64) = (1.0, 0.02);

/// The five topics of one run must cover the same time span (within
/// [`SPAN_TOLERANCE`]): a block whose length field was damaged, or whose
/// arrays were extended, stretches its topic far past the others.
fn check_spans(path: &Path, run: &RunTelemetry) -> Result<()> {
    let mut spans: Vec<(&str, u64, u64)> = Vec::new();
    for w in Wheel::ALL {
        let t = &run.wheels[w.index()].time_ns;
        if let (Some(a), Some(b)) = (t.iter().min(), t.iter().max()) {
            spans.push((w.topic(), *a, *b));
        }
    }
    let t = &run.vehicle.time_ns;
    if let (Some(a), Some(b)) = (t.iter().min(), t.iter().max()) {
        spans.push((VEHICLE_TOPIC, *a, *b));
    }
    let (Some(start), Some(end)) = (
        spans.iter().map(|s| s.1).min(),
        spans.iter().map(|s| s.2).max(),
    ) else {
        return Ok(());
    };
    let longest_s = (end - start) as f64 / 1e9;
    let tol_s = SPAN_TOLERANCE.0.max(SPAN_TOLERANCE.1 * longest_s);
    // The reference is the median topic, so that one damaged topic stands out.
    let mut ends: Vec<u64> = spans.iter().map(|s| s.2).collect();
    let mut starts: Vec<u64> = spans.iter().map(|s| s.1).collect();
    ends.sort_unstable();
    starts.sort_unstable();
    let (mid_start, mid_end) = (starts[starts.len() / 2], ends[ends.len() / 2]);
    for (topic, a, b) in spans {
        let off_s = (b.abs_diff(mid_end).max(a.abs_diff(mid_start))) as f64 / 1e9;
        if off_s > tol_s {
            return Err(IngestError::invalid(
                path,
                format!("topic {topic}"),
                format!(
                    "spans {:.3}..{:.3} s while the other topics span {:.3}..{:.3} s \
                     ({off_s:.1} s apart, more than the {tol_s:.1} s allowed): \
                     a block is longer than its period and the run allow",
                    a as f64 / 1e9,
                    b as f64 / 1e9,
                    mid_start as f64 / 1e9,
                    mid_end as f64 / 1e9
                ),
            ));
        }
    }
    Ok(())
}

/// What a channel's messages are, decided once per channel.
#[derive(Debug, Clone)]
enum ChannelKind {
    /// A topic this reader does not know: its messages are counted, not read.
    Ignored,
    /// One wheel's (`Some`) or the vehicle's (`None`) telemetry.
    Telemetry(Option<Wheel>, Encoding),
    /// A tirewear topic that cannot be read: the error for its messages.
    Invalid(String),
}

impl ChannelKind {
    fn of(channel: &mcap::Channel) -> Self {
        let topic = channel.topic.as_str();
        let wheel = Wheel::from_topic(topic);
        if wheel.is_none() && topic != VEHICLE_TOPIC {
            return Self::Ignored;
        }
        let schema = channel
            .schema
            .as_ref()
            .map(|s| s.name.as_str())
            .unwrap_or("");
        if channel.message_encoding != "protobuf" {
            return Self::Invalid(format!(
                "message encoding is '{}', expected 'protobuf'",
                channel.message_encoding
            ));
        }
        match (wheel, schema) {
            (Some(_), TIRE_SAMPLE) | (None, VEHICLE_SAMPLE) => {
                Self::Telemetry(wheel, Encoding::Sample)
            }
            (Some(_), TIRE_BLOCK) | (None, VEHICLE_BLOCK) => {
                Self::Telemetry(wheel, Encoding::Block)
            }
            _ => Self::Invalid(format!(
                "schema '{schema}' is not a tirewear.v1 schema for this topic"
            )),
        }
    }
}

/// Where a message sits, for its errors.
struct MessageAt<'a> {
    topic: &'a str,
    sequence: u32,
    log_time: u64,
}

impl MessageAt<'_> {
    fn record(&self) -> String {
        format!(
            "topic {}, message sequence {} at log_time {} ns",
            self.topic, self.sequence, self.log_time
        )
    }
}

/// Decodes one message into `run`: straight from its bytes where they are
/// in the form tirewear writes (`protowire`), through `prost` otherwise.
fn decode_into(
    run: &mut RunTelemetry,
    path: &Path,
    kind: &ChannelKind,
    at: &MessageAt,
    data: &[u8],
) -> Result<()> {
    let (wheel, encoding) = match kind {
        ChannelKind::Ignored => {
            run.ignored_messages += 1;
            return Ok(());
        }
        ChannelKind::Invalid(what) => {
            return Err(IngestError::invalid(path, at.record(), what.as_str()));
        }
        ChannelKind::Telemetry(wheel, encoding) => (*wheel, *encoding),
    };
    match run.encoding {
        None => run.encoding = Some(encoding),
        Some(e) if e != encoding => {
            return Err(IngestError::invalid(
                path,
                at.record(),
                "file mixes per-sample and block messages",
            ));
        }
        _ => {}
    }
    let undecodable = |e: prost::DecodeError| {
        let schema = match (wheel, encoding) {
            (Some(_), Encoding::Sample) => TIRE_SAMPLE,
            (Some(_), Encoding::Block) => TIRE_BLOCK,
            (None, Encoding::Sample) => VEHICLE_SAMPLE,
            (None, Encoding::Block) => VEHICLE_BLOCK,
        };
        IngestError::invalid(path, at.record(), format!("cannot decode {schema}: {e}"))
    };
    let bad_block = |what: String| IngestError::invalid(path, at.record(), what);
    match (wheel, encoding) {
        (Some(w), Encoding::Sample) => {
            let series = &mut run.wheels[w.index()];
            if !series.push_sample_bytes(at.log_time, data) {
                let s = proto::TireSample::decode(data).map_err(undecodable)?;
                series.push_sample(at.log_time, &s);
            }
        }
        (Some(w), Encoding::Block) => {
            let series = &mut run.wheels[w.index()];
            match series.push_block_bytes(data) {
                Some(pushed) => pushed.map_err(bad_block)?,
                None => {
                    let b = proto::TireBlock::decode(data).map_err(undecodable)?;
                    series.push_block(&b).map_err(bad_block)?;
                }
            }
        }
        (None, Encoding::Sample) => {
            if !run.vehicle.push_sample_bytes(at.log_time, data) {
                let s = proto::VehicleSample::decode(data).map_err(undecodable)?;
                run.vehicle.push_sample(at.log_time, &s);
            }
        }
        (None, Encoding::Block) => match run.vehicle.push_block_bytes(data) {
            Some(pushed) => pushed.map_err(bad_block)?,
            None => {
                let b = proto::VehicleBlock::decode(data).map_err(undecodable)?;
                run.vehicle.push_block(&b).map_err(bad_block)?;
            }
        },
    }
    Ok(())
}

/// The summary section, read with the file size and the record-length limit,
/// so a damaged summary is an error rather than an abort.
fn read_summary(path: &Path, bytes: &[u8]) -> Result<Option<mcap::Summary>> {
    let mc = |source| IngestError::Mcap {
        path: path.to_path_buf(),
        source,
    };
    let opts = mcap::sans_io::SummaryReaderOptions::default()
        .with_file_size(bytes.len() as u64)
        .with_record_length_limit(RECORD_LENGTH_LIMIT);
    let mut reader = mcap::sans_io::SummaryReader::new_with_options(opts);
    let mut pos: usize = 0;
    while let Some(event) = reader.next_event() {
        match event.map_err(mc)? {
            mcap::sans_io::SummaryReadEvent::ReadRequest(n) => {
                let end = (pos + n).min(bytes.len());
                let buf = reader.insert(end - pos);
                buf.copy_from_slice(&bytes[pos..end]);
                reader.notify_read(end - pos);
                pos = end;
            }
            mcap::sans_io::SummaryReadEvent::SeekRequest(to) => {
                let target = match to {
                    std::io::SeekFrom::Start(o) => o as i128,
                    std::io::SeekFrom::End(o) => bytes.len() as i128 + o as i128,
                    std::io::SeekFrom::Current(o) => pos as i128 + o as i128,
                };
                if target < 0 || target > bytes.len() as i128 {
                    return Err(IngestError::invalid(
                        path,
                        "summary",
                        format!("seek to {target} outside the file"),
                    ));
                }
                pos = target as usize;
                reader.notify_seeked(pos as u64);
            }
        }
    }
    Ok(reader.finish())
}

/// The start magic and the header record must be intact: the indexed path
/// would otherwise never look at them.
fn check_header(path: &Path, bytes: &[u8]) -> Result<()> {
    const MAGIC: &[u8] = b"\x89MCAP0\r\n";
    let bad = |what: &str| Err(IngestError::invalid(path, "header", what.to_string()));
    if bytes.len() < 17 || &bytes[..8] != MAGIC {
        return bad("not an MCAP file (bad start magic or too short)");
    }
    if bytes[8] != 0x01 {
        return bad("the first record is not a header record");
    }
    let len = u64::from_le_bytes(bytes[9..17].try_into().expect("8 bytes"));
    if len > RECORD_LENGTH_LIMIT as u64 || 17 + len > bytes.len() as u64 {
        return bad(&format!("header record length {len} is corrupt"));
    }
    Ok(())
}

/// MCAP opcodes and fixed sizes this module reads directly.
const OP_CHUNK: u8 = 0x06;
const OP_DATA_END: u8 = 0x0F;
const OP_FOOTER: u8 = 0x02;
/// Footer record: opcode, length, summary start, summary offset start, CRC.
const FOOTER_LEN: usize = 1 + 8 + 8 + 8 + 4;
/// DataEnd record: opcode, length, data-section CRC.
const DATA_END_LEN: usize = 1 + 8 + 4;
const MAGIC_LEN: usize = 8;

fn le_u64(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

fn le_u32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// What a run's MCAP file holds, read from its records' headers alone
/// (nothing decompressed or decoded), to estimate the memory reading it
/// takes ([`crate::kpi::run_memory_need`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MessageVolume {
    /// Bytes of its messages once decompressed: the summary's chunk indexes'
    /// uncompressed sizes, or, for a file without them, a walk of the data
    /// section's records (a chunk's declared uncompressed size, any other
    /// record's length). Each chunk counts at most the record-length limit
    /// the reader enforces; where a record runs past the file, the rest of
    /// the file counts.
    pub bytes: u64,
    /// Its number of messages (the summary's statistics), where every
    /// schema is a per-sample one (`TireSample`, `VehicleSample`): each such
    /// message is one sample, whatever its size.
    pub per_sample_messages: Option<u64>,
}

/// The [`MessageVolume`] of the MCAP file at `path`: from its summary, or
/// by walking its data section where the summary has no chunk index.
pub(crate) fn message_volume(path: &Path) -> Result<MessageVolume> {
    let (file, _) = crate::ingest::open_regular(path)?;
    // SAFETY: as in `read_indexed`.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| IngestError::io(path, e))?;
    let bytes: &[u8] = &map;
    Ok(summary_volume(bytes).unwrap_or_else(|| MessageVolume {
        bytes: walked_uncompressed_bytes(bytes),
        per_sample_messages: None,
    }))
}

/// [`MessageVolume`] from the summary section; `None` without a footer, a
/// summary or a chunk index.
fn summary_volume(bytes: &[u8]) -> Option<MessageVolume> {
    const OP_SCHEMA: u8 = 0x03;
    const OP_CHUNK_INDEX: u8 = 0x08;
    const OP_STATISTICS: u8 = 0x0B;
    let footer = bytes.len().checked_sub(MAGIC_LEN + FOOTER_LEN)?;
    if bytes[footer] != OP_FOOTER {
        return None;
    }
    let mut at = usize::try_from(le_u64(bytes, footer + 9)?).ok()?;
    if at == 0 || at > footer {
        return None;
    }
    let (mut total, mut chunks) = (0u64, 0usize);
    // The summary need not list the schemas: with none seen, nothing is
    // known of the messages' form.
    let (mut messages, mut schemas, mut all_per_sample) = (None, 0usize, true);
    while at < footer {
        let (op, body, end) = record_at(bytes, at, footer)?;
        let len = end - body;
        match op {
            // The uncompressed size is the record's last field.
            OP_CHUNK_INDEX if len >= 8 => {
                total += le_u64(bytes, end - 8)?.min(RECORD_LENGTH_LIMIT as u64);
                chunks += 1;
            }
            // The message count is the record's first field.
            OP_STATISTICS => messages = le_u64(bytes, body).filter(|_| len >= 8),
            // Its id (u16), then its name (u32-prefixed).
            OP_SCHEMA => {
                let n = le_u32(bytes, body + 2)? as usize;
                let name = bytes.get(body + 6..(body + 6).checked_add(n)?.min(end))?;
                all_per_sample &= name.ends_with(b"Sample");
                schemas += 1;
            }
            _ => {}
        }
        at = end;
    }
    (chunks > 0).then_some(MessageVolume {
        bytes: total,
        per_sample_messages: messages.filter(|_| all_per_sample && schemas > 0),
    })
}

/// The data section walked record by record from the start magic.
fn walked_uncompressed_bytes(bytes: &[u8]) -> u64 {
    let mut at = MAGIC_LEN;
    let mut total = 0u64;
    while let Some((op, body, end)) = record_at(bytes, at, bytes.len()) {
        let len = (end - body) as u64;
        match op {
            OP_DATA_END => return total,
            // Start and end times, then the uncompressed size.
            OP_CHUNK => {
                total += le_u64(bytes, body + 16)
                    .unwrap_or(len)
                    .min(RECORD_LENGTH_LIMIT as u64)
            }
            _ => total += len,
        }
        at = end;
    }
    total + bytes.len().saturating_sub(at) as u64
}

/// The record starting at `at`: its opcode, where its body starts and
/// where it ends; `None` where its length field is missing or runs past
/// `limit`.
fn record_at(bytes: &[u8], at: usize, limit: usize) -> Option<(u8, usize, usize)> {
    let len = usize::try_from(le_u64(bytes, at.checked_add(1)?)?).ok()?;
    let body = at.checked_add(9)?;
    let end = body.checked_add(len).filter(|&e| e <= limit)?;
    Some((bytes[at], body, end))
}

/// Checks the summary-section and data-section CRCs the writer stored (a
/// stored 0 means "not computed" and is skipped). Damage there would
/// otherwise pass unseen: the indexed path reads neither section whole.
/// A footer that does not parse is left to the summary reader.
fn check_file_crcs(path: &Path, bytes: &[u8]) -> Result<()> {
    let len = bytes.len();
    let Some(footer) = len.checked_sub(MAGIC_LEN + FOOTER_LEN) else {
        return Ok(());
    };
    if bytes[footer] != OP_FOOTER || le_u64(bytes, footer + 1) != Some(20) {
        return Ok(());
    }
    let summary_start = le_u64(bytes, footer + 9).unwrap_or(0);
    let summary_crc = le_u32(bytes, footer + 25).unwrap_or(0);
    // The summary CRC starts right after DataEnd: at the summary, or at the
    // footer when the summary is empty, and runs up to the CRC field itself.
    let crc_start = if summary_start == 0 {
        footer
    } else {
        summary_start as usize
    };
    if crc_start > footer {
        return Err(IngestError::invalid(
            path,
            "footer",
            format!("summary_start {summary_start} is past the footer at {footer}"),
        ));
    }
    if summary_crc != 0 {
        let got = crc32fast::hash(&bytes[crc_start..footer + 25]);
        if got != summary_crc {
            return Err(IngestError::invalid(
                path,
                format!("summary section at offset {crc_start}"),
                format!(
                    "CRC mismatch (stored {summary_crc:#010x}, computed {got:#010x}): the file is damaged"
                ),
            ));
        }
    }
    let Some(data_end) = crc_start.checked_sub(DATA_END_LEN) else {
        return Ok(());
    };
    if bytes[data_end] != OP_DATA_END || le_u64(bytes, data_end + 1) != Some(4) {
        return Err(IngestError::invalid(
            path,
            format!("offset {data_end}"),
            "no DataEnd record before the summary section: the file is damaged",
        ));
    }
    check_data_crc(path, bytes, data_end).map(|_| ())
}

/// Checks the data-section CRC stored in the DataEnd record at `data_end`;
/// returns whether there was one to check (0 means "not computed").
fn check_data_crc(path: &Path, bytes: &[u8], data_end: usize) -> Result<bool> {
    let stored = le_u32(bytes, data_end + 9).unwrap_or(0);
    if stored == 0 {
        return Ok(false);
    }
    let got = crc32fast::hash(&bytes[..data_end]);
    if got != stored {
        return Err(IngestError::invalid(
            path,
            "data section",
            format!(
                "CRC mismatch (stored {stored:#010x}, computed {got:#010x}): the file is damaged"
            ),
        ));
    }
    Ok(true)
}

/// One chunk's records, decompressed from the file and checked against the
/// chunk's own header (sizes, compression) and its CRC of the uncompressed
/// records. Sizes are bounded before any allocation.
/// A chunk's compressed bytes, checked against its index: (compression,
/// data, uncompressed size, CRC of the uncompressed records or 0).
fn chunk_data<'b>(
    path: &Path,
    bytes: &'b [u8],
    ci: &mcap::records::ChunkIndex,
) -> Result<(&'b str, &'b [u8], usize, u32)> {
    // The label is formatted only on an error: this runs once per chunk.
    let bad = |what: String| IngestError::invalid(path, chunk_label(ci.chunk_start_offset), what);
    let start = usize::try_from(ci.chunk_start_offset).unwrap_or(usize::MAX);
    let header = bytes
        .get(start..)
        .filter(|b| b.len() >= 1 + 8 + 8 + 8 + 8 + 4 + 4)
        .ok_or_else(|| {
            bad(format!(
                "starts past the end of the file ({} bytes)",
                bytes.len()
            ))
        })?;
    if header[0] != OP_CHUNK {
        return Err(bad(format!("opcode {:#04x} is not a chunk", header[0])));
    }
    let uncompressed_size = le_u64(header, 25).unwrap_or(0);
    let crc = le_u32(header, 33).unwrap_or(0);
    let name_len = le_u32(header, 37).unwrap_or(0) as usize;
    let name = header
        .get(41..41 + name_len.min(64))
        .filter(|_| name_len <= 64)
        .and_then(|b| std::str::from_utf8(b).ok())
        .ok_or_else(|| bad("compression name is damaged".into()))?;
    let data_len = le_u64(header, 41 + name_len).unwrap_or(u64::MAX);
    let data_at = 41 + name_len + 8;
    if name != ci.compression
        || uncompressed_size != ci.uncompressed_size
        || data_len != ci.compressed_size
    {
        return Err(bad(format!(
            "header (compression '{name}', {data_len} -> {uncompressed_size} bytes) disagrees \
             with the chunk index ('{}', {} -> {} bytes)",
            ci.compression, ci.compressed_size, ci.uncompressed_size
        )));
    }
    let limit = RECORD_LENGTH_LIMIT as u64;
    if uncompressed_size > limit || data_len > limit {
        return Err(bad(format!(
            "{data_len} -> {uncompressed_size} bytes is above the {limit}-byte record limit"
        )));
    }
    let data = usize::try_from(data_len)
        .ok()
        .and_then(|n| header.get(data_at..data_at + n))
        .ok_or_else(|| {
            bad(format!(
                "{data_len} bytes run past the end of the file ({} bytes)",
                bytes.len()
            ))
        })?;
    Ok((name, data, uncompressed_size as usize, crc))
}

/// How errors name a chunk.
fn chunk_label(chunk_start_offset: u64) -> String {
    format!("chunk at offset {chunk_start_offset}")
}

/// What decoding chunks reuses from one chunk to the next on a thread: a
/// zstd context and the buffer the records are decompressed into. A fresh
/// context and buffer per chunk cost a context's set-up and the page faults
/// of touching new memory for every chunk.
#[derive(Default)]
struct ChunkScratch {
    zstd: Option<zstd::bulk::Decompressor<'static>>,
    buf: Vec<u8>,
}

impl ChunkScratch {
    /// Decompresses a zstd frame of `size` bytes into the buffer.
    fn zstd(&mut self, data: &[u8], size: usize) -> std::io::Result<&[u8]> {
        let dec = match &mut self.zstd {
            Some(d) => d,
            None => self.zstd.insert(zstd::bulk::Decompressor::new()?),
        };
        self.buf.clear();
        self.buf.reserve(size);
        dec.decompress_to_buffer(data, &mut self.buf)?;
        Ok(&self.buf)
    }
}

/// A chunk's records, decompressed (into `scratch`, or borrowed from the
/// file when stored uncompressed) and checked against the chunk's CRC.
fn chunk_records<'a>(
    path: &Path,
    bytes: &'a [u8],
    ci: &mcap::records::ChunkIndex,
    scratch: &'a mut ChunkScratch,
) -> Result<&'a [u8]> {
    // The label is formatted only on an error: this runs once per chunk.
    let bad = |what: String| IngestError::invalid(path, chunk_label(ci.chunk_start_offset), what);
    let (name, data, size, crc) = chunk_data(path, bytes, ci)?;
    let out: &[u8] = match name {
        "" => data,
        "zstd" => scratch
            .zstd(data, size)
            .map_err(|e| bad(format!("zstd: {e}")))?,
        "lz4" => {
            use std::io::Read;
            scratch.buf.clear();
            scratch.buf.reserve(size);
            lz4::Decoder::new(data)
                .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut scratch.buf))
                .map_err(|e| bad(format!("lz4: {e}")))?;
            &scratch.buf
        }
        other => return Err(bad(format!("unsupported compression '{other}'"))),
    };
    if out.len() != size {
        return Err(bad(format!(
            "decompresses to {} bytes, the header says {size}",
            out.len()
        )));
    }
    if crc != 0 {
        let got = crc32fast::hash(out);
        if got != crc {
            return Err(bad(format!(
                "CRC of the uncompressed records does not match (stored {crc:#010x}, \
                 computed {got:#010x}): the chunk is damaged"
            )));
        }
    }
    Ok(out)
}

/// The physical reference for decoding: decompresses every chunk of an
/// indexed MCAP file with zstd (or lz4) and nothing else — no CRC, no
/// parsing — and returns the uncompressed bytes. `tirewear bench` times it
/// against [`read_telemetry`] over the same files.
pub(crate) fn decompress_only(path: &Path) -> Result<u64> {
    let (file, _) = crate::ingest::open_regular(path)?;
    // SAFETY: as in `read_indexed`.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| IngestError::io(path, e))?;
    let bytes: &[u8] = &map;
    let summary = read_summary(path, bytes)?
        .ok_or_else(|| IngestError::invalid(path, "summary", "no summary to find chunks by"))?;
    // The same context and buffer reuse as `read_indexed`, so that the
    // reference gains what the reader gains from it.
    let mut scratch = ChunkScratch::default();
    let mut total = 0u64;
    for ci in &summary.chunk_indexes {
        let (name, data, size, _) = chunk_data(path, bytes, ci)?;
        total += match name {
            "zstd" => scratch
                .zstd(data, size)
                .map_err(|e| IngestError::invalid(path, "chunk", format!("zstd: {e}")))?
                .len() as u64,
            _ => chunk_records(path, bytes, ci, &mut scratch)?.len() as u64,
        };
    }
    Ok(total)
}

/// Parallel path: the chunks found by the summary's index, each decompressed
/// and decoded on its own (rayon) from the memory map, then appended in file
/// order. `None` when the file has no usable summary or chunk index (read it
/// linearly).
/// The file's and every chunk's CRCs are checked (where the writer stored them).
fn read_indexed(path: &Path) -> Result<Option<RunTelemetry>> {
    use rayon::prelude::*;
    let (file, _) = crate::ingest::open_regular(path)?;
    // SAFETY: the map is read-only and the file is not modified while we read it;
    // a concurrent writer could only make us read wrong bytes, which decode as errors.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| IngestError::io(path, e))?;
    let bytes: &[u8] = &map;
    check_header(path, bytes)?;
    // Before any record is parsed: the mcap crate sizes strings from their
    // length prefix (up to 4 GiB) before checking them against the record.
    check_file_crcs(path, bytes)?;
    let Some(summary) = read_summary(path, bytes).ok().flatten() else {
        return Ok(None);
    };
    if summary.chunk_indexes.is_empty() {
        return Ok(None);
    }
    let mut chunks = summary.chunk_indexes.clone();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    let kinds: BTreeMap<u16, (ChannelKind, &str)> = summary
        .channels
        .iter()
        .map(|(&id, c)| (id, (ChannelKind::of(c), c.topic.as_str())))
        .collect();
    let parts: Vec<Result<RunTelemetry>> = chunks
        .par_iter()
        .map_init(
            || (Vec::new(), ChunkScratch::default()),
            |(order, scratch), ci| {
                let records = chunk_records(path, bytes, ci, scratch)?;
                let offset = ci.chunk_start_offset;
                chunk_messages(path, offset, records, order)?;
                let mut part = RunTelemetry::default();
                reserve_for(&mut part, &kinds, order);
                for m in order.iter() {
                    let (kind, topic) = kinds.get(&m.channel).ok_or_else(|| {
                        IngestError::invalid(
                            path,
                            format!("{}, message sequence {}", chunk_label(offset), m.sequence),
                            format!("unknown channel {}", m.channel),
                        )
                    })?;
                    let at = MessageAt {
                        topic,
                        sequence: m.sequence,
                        log_time: m.log_time,
                    };
                    decode_into(&mut part, path, kind, &at, &records[m.data.clone()])?;
                }
                Ok(part)
            },
        )
        .collect();
    let parts = parts.into_iter().collect::<Result<Vec<_>>>()?;
    let mut run = RunTelemetry::default();
    for (i, w) in run.wheels.iter_mut().enumerate() {
        w.reserve(parts.iter().map(|p| p.wheels[i].len()).sum());
    }
    run.vehicle
        .reserve(parts.iter().map(|p| p.vehicle.len()).sum());
    for part in parts {
        match (run.encoding, part.encoding) {
            (Some(a), Some(b)) if a != b => {
                return Err(IngestError::invalid(
                    path,
                    "chunks",
                    "file mixes per-sample and block messages",
                ));
            }
            (None, e) => run.encoding = e,
            _ => {}
        }
        run.ignored_messages += part.ignored_messages;
        for (w, p) in run.wheels.iter_mut().zip(part.wheels) {
            w.append(p);
        }
        run.vehicle.append(part.vehicle);
    }
    run.estimated = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == IMPORT_METADATA)
        .and_then(|m| mcap::read::metadata(bytes, m).ok())
        .and_then(|m| m.metadata.get("estimated").cloned());
    Ok(Some(run))
}

/// Room in a chunk's part for every sample its messages can hold, so that
/// its columns do not grow by copying: a per-sample message holds one
/// sample, a block at most its bytes over one sample's packed values
/// (tire: 11 floats; vehicle: 3 floats and a double). Bounded by the
/// chunk's own bytes, whatever they hold.
fn reserve_for(
    part: &mut RunTelemetry,
    kinds: &BTreeMap<u16, (ChannelKind, &str)>,
    messages: &[ChunkMessage],
) {
    const TIRE_BLOCK_BYTES: usize = 11 * 4;
    const VEHICLE_BLOCK_BYTES: usize = 3 * 4 + 8;
    let (mut wheels, mut vehicle) = ([0usize; 4], 0usize);
    for m in messages {
        if let Some((ChannelKind::Telemetry(wheel, encoding), _)) = kinds.get(&m.channel) {
            let bytes = m.data.len();
            let (slot, per_sample) = match wheel {
                Some(w) => (&mut wheels[w.index()], TIRE_BLOCK_BYTES),
                None => (&mut vehicle, VEHICLE_BLOCK_BYTES),
            };
            *slot += match encoding {
                Encoding::Sample => 1,
                Encoding::Block => bytes / per_sample,
            };
        }
    }
    for (series, n) in part.wheels.iter_mut().zip(wheels) {
        series.reserve(n);
    }
    part.vehicle.reserve(vehicle);
}

/// A message record inside a chunk's records.
struct ChunkMessage {
    channel: u16,
    sequence: u32,
    log_time: u64,
    /// Its data, as a range of the chunk's records.
    data: std::ops::Range<usize>,
}

/// The message records of one chunk's (decompressed, checked) records, in
/// log-time order with ties in file order: the order of the mcap crate's
/// indexed reader. Schema and channel records are skipped (the summary's
/// channels are the ones used); a record that runs past the end is an error.
fn chunk_messages(
    path: &Path,
    chunk_offset: u64,
    records: &[u8],
    out: &mut Vec<ChunkMessage>,
) -> Result<()> {
    const OP_MESSAGE: u8 = 0x05;
    // channel id u16, sequence u32, log_time u64, publish_time u64.
    const MESSAGE_HEADER: usize = 2 + 4 + 8 + 8;
    out.clear();
    let mut at = 0usize;
    while at < records.len() {
        let bad = |what: String| {
            IngestError::invalid(
                path,
                format!(
                    "{}, record at offset {at} of its records",
                    chunk_label(chunk_offset)
                ),
                what,
            )
        };
        let len = le_u64(records, at + 1)
            .and_then(|l| usize::try_from(l).ok())
            .filter(|&l| l <= records.len() - at - 9)
            .ok_or_else(|| {
                bad(format!(
                    "its length runs past the end of the chunk's {} bytes of records",
                    records.len()
                ))
            })?;
        let body = at + 9..at + 9 + len;
        if records[at] == OP_MESSAGE {
            if len < MESSAGE_HEADER {
                return Err(bad(format!(
                    "a message record of {len} bytes is shorter than its {MESSAGE_HEADER}-byte header"
                )));
            }
            let b = &records[body.clone()];
            out.push(ChunkMessage {
                channel: u16::from_le_bytes([b[0], b[1]]),
                sequence: le_u32(b, 2).unwrap_or(0),
                log_time: le_u64(b, 6).unwrap_or(0),
                data: body.start + MESSAGE_HEADER..body.end,
            });
        }
        at = body.end;
    }
    if !out.is_sorted_by_key(|m| m.log_time) {
        // Stable: equal log times keep their file order.
        out.sort_by_key(|m| m.log_time);
    }
    Ok(())
}

/// Walks the top-level records from the header to `DataEnd`, each length
/// checked against the file; returns DataEnd's offset. Records with strings
/// are checked too (their length prefixes must fit in the record) where no
/// data-section CRC vouches for them.
fn data_section_end(path: &Path, bytes: &[u8]) -> Result<usize> {
    let mut at = MAGIC_LEN;
    let mut unverified = Vec::new();
    loop {
        let len = le_u64(bytes, at + 1)
            .filter(|&l| l <= (bytes.len() - at - 9) as u64)
            .ok_or_else(|| {
                IngestError::invalid(
                    path,
                    format!("record at offset {at}"),
                    "its length runs past the end of the file (truncated or damaged), \
                     and there is no intact summary to read around it",
                )
            })? as usize;
        let op = bytes[at];
        if op == OP_DATA_END {
            if !check_data_crc(path, bytes, at)? {
                for (op, rec_at, rec_len) in unverified {
                    check_strings(path, op, rec_at, &bytes[rec_at + 9..rec_at + 9 + rec_len])?;
                }
            }
            return Ok(at);
        }
        unverified.push((op, at, len));
        at += 9 + len;
    }
}

/// The string, byte-array and map fields of a header, schema, channel or
/// metadata record must fit inside the record.
fn check_strings(path: &Path, op: u8, at: usize, body: &[u8]) -> Result<()> {
    // Field layout after any fixed-size prefix: each entry is a u32-prefixed field.
    let (skip, fields) = match op {
        0x01 => (0, 2), // header: profile, library
        0x03 => (2, 3), // schema: id; name, encoding, data
        0x04 => (4, 3), // channel: id, schema id; topic, encoding, metadata map
        0x0C => (0, 2), // metadata: name, map
        _ => return Ok(()),
    };
    let mut pos = skip;
    for _ in 0..fields {
        let n = le_u32(body, pos).map(|n| n as usize);
        match n.and_then(|n| (pos + 4).checked_add(n)) {
            Some(end) if end <= body.len() => pos = end,
            _ => {
                return Err(IngestError::invalid(
                    path,
                    format!("record at offset {at} (opcode {op:#04x})"),
                    "a string or map length runs past the record: the file is damaged",
                ));
            }
        }
    }
    Ok(())
}

/// Linear path: every record in file order, one thread (unchunked files,
/// files without a usable summary). Public so tests and benches can compare
/// paths. The data section is walked and checked first (its CRC, or the
/// string lengths where it has none); the summary is not read at all, so a
/// damaged one cannot derail the reader.
pub fn read_telemetry_linear(path: &Path) -> Result<RunTelemetry> {
    let (file, _) = crate::ingest::open_regular(path)?;
    // SAFETY: as in `read_indexed`.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| IngestError::io(path, e))?;
    let bytes: &[u8] = &map;
    check_header(path, bytes)?;
    let data_end = data_section_end(path, bytes)?;
    // The data section and DataEnd, closed by an empty footer and the magic.
    let mut tail = [0u8; FOOTER_LEN + MAGIC_LEN];
    tail[0] = OP_FOOTER;
    tail[1..9].copy_from_slice(&20u64.to_le_bytes());
    tail[FOOTER_LEN..].copy_from_slice(b"\x89MCAP0\r\n");
    let input = std::io::Read::chain(&bytes[..data_end + DATA_END_LEN], &tail[..]);
    let opts = mcap::sans_io::LinearReaderOptions::default()
        .with_record_length_limit(RECORD_LENGTH_LIMIT)
        .with_prevalidate_chunk_crcs(true);
    let reader = mcap::io::MessageReader::new_with_options(input, opts);
    let mut run = RunTelemetry::default();
    for msg in reader {
        let msg = msg.map_err(|source| IngestError::Mcap {
            path: path.to_path_buf(),
            source,
        })?;
        let at = MessageAt {
            topic: &msg.channel.topic,
            sequence: msg.sequence,
            log_time: msg.log_time,
        };
        decode_into(
            &mut run,
            path,
            &ChannelKind::of(&msg.channel),
            &at,
            &msg.data,
        )?;
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    //! The fast readers (`protowire`) against `prost`: on every message of
    //! every MCAP fixture (tirewear's writer and Python's), and on messages
    //! written in every other valid way a protobuf encoder may use, where the
    //! fast reader must give up and the `prost` route give the same series.
    use super::*;
    use rand::{Rng, SeedableRng};

    fn key(number: u32, wire: u32) -> Vec<u8> {
        varint_bytes(u64::from(number << 3 | wire))
    }

    fn varint_bytes(mut v: u64) -> Vec<u8> {
        let mut out = Vec::new();
        while v >= 0x80 {
            out.push((v as u8) | 0x80);
            v >>= 7;
        }
        out.push(v as u8);
        out
    }

    /// A block through the route `decode_into` takes: fast, else prost.
    fn block_any(data: &[u8]) -> (bool, std::result::Result<WheelSeries, String>) {
        let mut s = WheelSeries::default();
        match s.push_block_bytes(data) {
            Some(r) => (true, r.map(|()| s)),
            None => (false, block_prost(data)),
        }
    }

    fn block_prost(data: &[u8]) -> std::result::Result<WheelSeries, String> {
        let mut s = WheelSeries::default();
        let b = proto::TireBlock::decode(data).map_err(|e| e.to_string())?;
        s.push_block(&b)?;
        Ok(s)
    }

    fn sample_any(data: &[u8]) -> (bool, std::result::Result<WheelSeries, String>) {
        let mut s = WheelSeries::default();
        if s.push_sample_bytes(5, data) {
            return (true, Ok(s));
        }
        (false, sample_prost(data))
    }

    fn sample_prost(data: &[u8]) -> std::result::Result<WheelSeries, String> {
        let mut s = WheelSeries::default();
        let m = proto::TireSample::decode(data).map_err(|e| e.to_string())?;
        s.push_sample(5, &m);
        Ok(s)
    }

    /// Every channel's bits (NaN payloads included), and the times.
    fn bits(s: &WheelSeries) -> (Vec<u64>, Vec<Vec<u32>>) {
        let channels = s
            .channels()
            .iter()
            .map(|c| c.iter().map(|x| x.to_bits()).collect())
            .collect();
        (s.time_ns.clone(), channels)
    }

    /// The same series bit for bit, or both an error.
    fn same(
        a: &std::result::Result<WheelSeries, String>,
        b: &std::result::Result<WheelSeries, String>,
    ) -> bool {
        match (a, b) {
            (Ok(a), Ok(b)) => bits(a) == bits(b),
            (Err(_), Err(_)) => true,
            _ => false,
        }
    }

    /// The volume read from the records' headers against the mcap crate's
    /// summary and message stream, on every fixture (tirewear's and
    /// Python's writers), from the summary and by the walk of a copy cut
    /// before its summary.
    #[test]
    fn message_volume_agrees_with_the_mcap_crate() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
        for name in ["tiny-block", "tiny-sample", "python-block", "python-sample"] {
            let bytes = std::fs::read(dir.join(format!("{name}.mcap"))).unwrap();
            let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
            let uncompressed: u64 = summary
                .chunk_indexes
                .iter()
                .map(|c| c.uncompressed_size)
                .sum();
            let messages = mcap::MessageStream::new(&bytes).unwrap().count() as u64;
            let v = summary_volume(&bytes).unwrap();
            assert_eq!(v.bytes, uncompressed, "{name}");
            let per_sample = name.ends_with("sample");
            assert_eq!(
                v.per_sample_messages,
                per_sample.then_some(messages),
                "{name}"
            );
            // A summary that lists no schema (the spec allows it) says
            // nothing of the messages' form: their bytes count instead.
            let mut unlisted = bytes.clone();
            let footer = bytes.len() - MAGIC_LEN - FOOTER_LEN;
            let mut at = le_u64(&bytes, footer + 9).unwrap() as usize;
            while at < footer {
                if unlisted[at] == 0x03 {
                    unlisted[at] = 0x7F;
                }
                at += 9 + le_u64(&bytes, at + 1).unwrap() as usize;
            }
            let u = summary_volume(&unlisted).unwrap();
            assert_eq!(
                (u.bytes, u.per_sample_messages),
                (uncompressed, None),
                "{name}"
            );

            // Without a summary (the data section, DataEnd, nothing after):
            // the chunks' sizes plus the records between them.
            let data_end = data_section_end(Path::new(name), &bytes).unwrap();
            let cut = &bytes[..data_end + DATA_END_LEN];
            assert_eq!(summary_volume(cut), None, "{name}");
            let compressed: u64 = summary.chunk_indexes.iter().map(|c| c.chunk_length).sum();
            let between = data_end as u64 - MAGIC_LEN as u64 - compressed;
            let walked = walked_uncompressed_bytes(cut);
            assert!(
                (uncompressed..=uncompressed + between).contains(&walked),
                "{name}: {walked} outside {uncompressed}..={}",
                uncompressed + between
            );
        }
    }

    #[test]
    fn every_fixture_message_reads_the_same_fast_and_through_prost() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
        let mut fast = 0;
        for name in ["tiny-block", "tiny-sample", "python-block", "python-sample"] {
            let bytes = std::fs::read(dir.join(format!("{name}.mcap"))).unwrap();
            for msg in mcap::MessageStream::new(&bytes).unwrap() {
                let msg = msg.unwrap();
                let data = msg.data.as_ref();
                let (wheel, vehicle) = (
                    Wheel::from_topic(&msg.channel.topic).is_some(),
                    msg.channel.topic == VEHICLE_TOPIC,
                );
                let schema = msg.channel.schema.as_ref().unwrap().name.as_str();
                let took_fast = match schema {
                    TIRE_BLOCK if wheel => {
                        let (f, got) = block_any(data);
                        assert!(same(&got, &block_prost(data)), "{name}");
                        f
                    }
                    TIRE_SAMPLE if wheel => {
                        let (f, got) = sample_any(data);
                        assert!(same(&got, &sample_prost(data)), "{name}");
                        f
                    }
                    VEHICLE_BLOCK if vehicle => {
                        let mut a = VehicleSeries::default();
                        let f = a.push_block_bytes(data).unwrap().is_ok();
                        let mut b = VehicleSeries::default();
                        b.push_block(&proto::VehicleBlock::decode(data).unwrap())
                            .unwrap();
                        assert_eq!(format!("{a:?}"), format!("{b:?}"), "{name}");
                        f
                    }
                    VEHICLE_SAMPLE if vehicle => {
                        let mut a = VehicleSeries::default();
                        let f = a.push_sample_bytes(9, data);
                        let mut b = VehicleSeries::default();
                        b.push_sample(9, &proto::VehicleSample::decode(data).unwrap());
                        assert_eq!(format!("{a:?}"), format!("{b:?}"), "{name}");
                        f
                    }
                    other => panic!("{name}: unexpected schema {other}"),
                };
                // Both writers' messages take the fast route.
                assert!(took_fast, "{name}: {schema} fell back to prost");
                fast += 1;
            }
        }
        assert!(fast > 100, "{fast}");
    }

    /// A random block as prost writes it, and its channels by field number.
    fn random_block(rng: &mut impl Rng) -> (proto::TireBlock, Vec<(u32, Vec<f32>)>) {
        let n = rng.random_range(0..6);
        let mut channels = Vec::new();
        for number in 3..=13u32 {
            let v: Vec<f32> = (0..n)
                .map(|_| f32::from_bits(rng.random::<u32>()))
                .collect();
            channels.push((number, v));
        }
        let c = |i: usize| channels[i].1.clone();
        let block = proto::TireBlock {
            start_time_ns: rng.random_range(0..1u64 << 40),
            sample_period_ns: rng.random_range(0..3) * 1_000_000,
            vx_mps: c(0),
            vy_mps: c(1),
            omega_radps: c(2),
            rolling_radius_m: c(3),
            fx_n: c(4),
            fy_n: c(5),
            fz_n: c(6),
            t_surface_c: c(7),
            t_inner_c: c(8),
            pressure_pa: c(9),
            camber_deg: c(10),
        };
        (block, channels)
    }

    /// The same block written by hand: fields in a random order, the times
    /// with redundant varint bytes, each channel packed, split into two
    /// packed runs, or unpacked, and maybe an unknown field.
    fn rewritten(
        b: &proto::TireBlock,
        channels: &[(u32, Vec<f32>)],
        rng: &mut impl Rng,
    ) -> Vec<Vec<u8>> {
        let mut fields: Vec<Vec<u8>> = Vec::new();
        for (number, value) in [(1, b.start_time_ns), (2, b.sample_period_ns)] {
            let mut f = key(number, 0);
            let mut v = varint_bytes(value);
            if rng.random_bool(0.5) {
                // 0x80 continuation with a zero group: same value, longer.
                let last = v.pop().unwrap();
                v.extend([last | 0x80, 0x00]);
            }
            f.extend(v);
            fields.push(f);
        }
        // Half the blocks keep every channel in one packed run (the fast
        // reader takes them), half mix the three ways.
        let mixed = rng.random_bool(0.5);
        for (number, values) in channels {
            let packed = |vals: &[f32]| {
                let mut f = key(*number, 2);
                f.extend(varint_bytes(4 * vals.len() as u64));
                f.extend(vals.iter().flat_map(|x| x.to_le_bytes()));
                f
            };
            match if mixed { rng.random_range(0..3) } else { 0 } {
                0 => fields.push(packed(values)),
                1 => {
                    let cut = rng.random_range(0..=values.len());
                    fields.push(packed(&values[..cut]));
                    fields.push(packed(&values[cut..]));
                }
                _ => {
                    let mut f = Vec::new();
                    for x in values {
                        f.extend(key(*number, 5));
                        f.extend(x.to_le_bytes());
                    }
                    fields.push(f);
                }
            }
        }
        if rng.random_bool(0.3) {
            let mut f = key(99, 2);
            f.extend([3, 1, 2, 3]);
            fields.push(f);
        }
        // File order as written or reversed (split runs then concatenate
        // the other way round, for prost as for the fast reader).
        let mut order: Vec<usize> = (0..fields.len()).collect();
        if rng.random_bool(0.5) {
            order.reverse();
        }
        order.into_iter().map(|i| fields[i].clone()).collect()
    }

    #[test]
    fn blocks_written_any_valid_way_read_as_prost_reads_them() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (mut fast, mut fallback) = (0, 0);
        for _ in 0..2000 {
            let (block, channels) = random_block(&mut rng);
            let canonical = block.encode_to_vec();
            let (f, got) = block_any(&canonical);
            assert!(f, "prost's own encoding takes the fast route");
            assert!(same(&got, &block_prost(&canonical)));
            let fields = rewritten(&block, &channels, &mut rng);
            let data: Vec<u8> = fields.concat();
            let (f, got) = block_any(&data);
            assert!(same(&got, &block_prost(&data)), "{data:?}");
            if f {
                fast += 1
            } else {
                fallback += 1
            }
            // Damaged: cut anywhere, or one byte changed.
            let cut = rng.random_range(0..=data.len());
            assert!(same(&block_any(&data[..cut]).1, &block_prost(&data[..cut])));
            if !data.is_empty() {
                let mut flipped = data.clone();
                let i = rng.random_range(0..data.len());
                flipped[i] ^= 1 << rng.random_range(0..8);
                assert!(
                    same(&block_any(&flipped).1, &block_prost(&flipped)),
                    "{flipped:?}"
                );
            }
        }
        // Both routes were exercised.
        assert!(
            fast > 50 && fallback > 500,
            "{fast} fast, {fallback} through prost"
        );
    }

    #[test]
    fn samples_written_any_valid_way_read_as_prost_reads_them() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        for _ in 0..2000 {
            let values: Vec<f32> = (0..11)
                .map(|_| {
                    if rng.random_bool(0.2) {
                        0.0
                    } else {
                        f32::from_bits(rng.random::<u32>())
                    }
                })
                .collect();
            let m = proto::TireSample {
                vx_mps: values[0],
                vy_mps: values[1],
                omega_radps: values[2],
                rolling_radius_m: values[3],
                fx_n: values[4],
                fy_n: values[5],
                fz_n: values[6],
                t_surface_c: values[7],
                t_inner_c: values[8],
                pressure_pa: values[9],
                camber_deg: values[10],
            };
            let canonical = m.encode_to_vec();
            let (f, got) = sample_any(&canonical);
            assert!(f);
            assert!(same(&got, &sample_prost(&canonical)));
            // Fields in any order, some twice (the last one counts), maybe
            // an unknown one.
            let mut fields: Vec<Vec<u8>> = (1..=11u32)
                .map(|n| {
                    let mut f = key(n, 5);
                    f.extend(values[n as usize - 1].to_le_bytes());
                    f
                })
                .collect();
            let twice = rng.random_range(0..11usize);
            let mut again = key(twice as u32 + 1, 5);
            again.extend(rng.random::<u32>().to_le_bytes());
            fields.push(again);
            if rng.random_bool(0.3) {
                fields.push([key(20, 0), vec![7]].concat());
            }
            for i in (1..fields.len() - 1).rev() {
                fields.swap(i, rng.random_range(0..=i));
            }
            let data = fields.concat();
            assert!(same(&sample_any(&data).1, &sample_prost(&data)));
            let cut = rng.random_range(0..=data.len());
            assert!(same(
                &sample_any(&data[..cut]).1,
                &sample_prost(&data[..cut])
            ));
            let mut flipped = data.clone();
            let i = rng.random_range(0..data.len());
            flipped[i] ^= 1 << rng.random_range(0..8);
            assert!(same(&sample_any(&flipped).1, &sample_prost(&flipped)));
        }
    }
}

#[cfg(test)]
mod chunk_tests {
    use super::*;

    fn record(op: u8, body: &[u8]) -> Vec<u8> {
        let mut r = vec![op];
        r.extend((body.len() as u64).to_le_bytes());
        r.extend(body);
        r
    }

    fn message(channel: u16, sequence: u32, log_time: u64, data: &[u8]) -> Vec<u8> {
        let mut b = channel.to_le_bytes().to_vec();
        b.extend(sequence.to_le_bytes());
        b.extend(log_time.to_le_bytes());
        b.extend(0u64.to_le_bytes());
        b.extend(data);
        record(0x05, &b)
    }

    #[test]
    fn messages_come_in_log_time_order_with_ties_in_file_order() {
        let records = [
            record(0x04, b"a channel record, skipped"),
            message(1, 0, 30, b"c"),
            message(2, 1, 10, b"a"),
            message(1, 2, 30, b"d"),
            message(3, 3, 20, b"b"),
        ]
        .concat();
        let mut out = Vec::new();
        chunk_messages(Path::new("f.mcap"), 0, &records, &mut out).unwrap();
        let got: Vec<(u16, u32, u64, &[u8])> = out
            .iter()
            .map(|m| (m.channel, m.sequence, m.log_time, &records[m.data.clone()]))
            .collect();
        let want: Vec<(u16, u32, u64, &[u8])> = vec![
            (2, 1, 10, b"a"),
            (3, 3, 20, b"b"),
            (1, 0, 30, b"c"),
            (1, 2, 30, b"d"),
        ];
        assert_eq!(got, want);
    }

    #[test]
    fn a_record_past_the_end_or_a_short_message_is_named() {
        let mut records = message(1, 0, 5, b"xyz");
        records.truncate(records.len() - 1);
        let mut out = Vec::new();
        let e = chunk_messages(Path::new("f.mcap"), 8, &records, &mut out)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.mcap") && e.contains("chunk at offset 8, record at offset 0"),
            "{e}"
        );
        assert!(e.contains("past the end"), "{e}");
        let short = record(0x05, &[0; 10]);
        let e = chunk_messages(Path::new("f.mcap"), 0, &short, &mut out)
            .unwrap_err()
            .to_string();
        assert!(e.contains("shorter than its 22-byte header"), "{e}");
        // Eight bytes: not even a record's opcode and length.
        let e = chunk_messages(Path::new("f.mcap"), 0, &[5; 8], &mut out).unwrap_err();
        assert!(e.to_string().contains("past the end"), "{e}");
    }
}
