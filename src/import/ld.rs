//! MoTeC i2 `.ld` logs through the `motec-i2` crate. The crate panics or
//! loops on some damaged files (a cycle in the channel list, an unknown
//! sample type, a non-zero offset), so the channel list and every channel's
//! type and data range are checked here first, and values are decoded here
//! (`value = (raw / scale · 10^−dec_places + offset) · mul`, the formula of
//! the reverse-engineered format).

use super::error::ImportError;
use super::log::{LogMeta, RawChannel, RawLog, parse_date, parse_time_of_day};
use motec_i2::{ChannelMetadata, Datatype, LDReader, Sample};
use std::io::Cursor;
use std::path::Path;

/// Size of one channel-metadata entry (bytes).
const ENTRY: usize = 124;
/// More channels than any logger writes: a longer list is damage.
const MAX_CHANNELS: usize = 65_536;

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes(s.try_into().expect("4 bytes")))
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    b.get(at..at + 2)
        .map(|s| u16::from_le_bytes(s.try_into().expect("2 bytes")))
}

/// Walks the channel list as the crate will, refusing what would make it
/// loop, panic or read past the end.
fn check_layout(path: &Path, b: &[u8]) -> Result<(), ImportError> {
    let bad = |record: String, what: String| ImportError::log(path, record, what);
    if u32_at(b, 0) != Some(0x40) {
        return Err(bad(
            "header".into(),
            "not a MoTeC .ld file (no 0x40 marker)".into(),
        ));
    }
    let mut at = u32_at(b, 8).ok_or_else(|| bad("header".into(), "truncated".into()))? as usize;
    let mut seen = std::collections::HashSet::new();
    let mut k = 0usize;
    while at != 0 {
        let rec = format!("channel {k} (metadata at byte {at})");
        if !seen.insert(at) || seen.len() > MAX_CHANNELS {
            return Err(bad(rec, "the channel list loops".into()));
        }
        if at + ENTRY > b.len() {
            return Err(bad(rec, "lies past the end of the file".into()));
        }
        let next = u32_at(b, at + 4).expect("in range") as usize;
        let data_addr = u32_at(b, at + 8).expect("in range") as usize;
        let count = u32_at(b, at + 12).expect("in range") as usize;
        let (ty, size) = (
            u16_at(b, at + 18).expect("in range"),
            u16_at(b, at + 20).expect("in range"),
        );
        let rate = u16_at(b, at + 22).expect("in range");
        let scale = u16_at(b, at + 28).expect("in range");
        let known = matches!((ty, size), (0 | 3 | 5, 2 | 4) | (7, 4));
        let empty_invalid = count == 0;
        if !known && !empty_invalid {
            return Err(bad(
                rec,
                format!("unknown sample type {ty} of {size} bytes"),
            ));
        }
        if known && data_addr + count * size as usize > b.len() {
            return Err(bad(
                rec,
                format!("its {count} samples run past the end of the file"),
            ));
        }
        if count > 0 && (rate == 0 || scale == 0) {
            return Err(bad(
                rec,
                format!("sample rate {rate} Hz, scale {scale}: must be > 0"),
            ));
        }
        at = next;
        k += 1;
    }
    Ok(())
}

fn decode(s: &Sample, c: &ChannelMetadata) -> f64 {
    let raw = match s {
        Sample::I16(v) => *v as f64,
        Sample::I32(v) => *v as f64,
        Sample::F32(v) => *v as f64,
    };
    // The offset is stored as 16 bits; loggers write it signed.
    (raw / c.scale as f64 * 10f64.powi(-(c.dec_places as i32)) + c.offset as i16 as f64)
        * c.mul as f64
}

/// Reads a `.ld` file (whole, up to the log size limit). Beacon channels
/// and empty channels are skipped.
pub(crate) fn read_ld(path: &Path) -> Result<RawLog, ImportError> {
    let bytes = std::fs::read(path).map_err(|e| ImportError::io(path, e))?;
    check_layout(path, &bytes)?;
    let mut cursor = Cursor::new(bytes);
    let mut reader = LDReader::new(&mut cursor);
    let i2 = |record: &str, e: motec_i2::I2Error| ImportError::log(path, record, e.to_string());
    let header = reader.read_header().map_err(|e| i2("header", e))?;
    let channels = reader.read_channels().map_err(|e| i2("channel list", e))?;
    let mut out = Vec::new();
    for c in &channels {
        if c.data_count == 0
            || matches!(
                c.datatype,
                Datatype::Beacon16 | Datatype::Beacon32 | Datatype::Invalid
            )
        {
            continue;
        }
        if matches!(c.datatype, Datatype::F16) {
            return Err(ImportError::Channel {
                path: path.to_path_buf(),
                channel: c.name.clone(),
                what: "16-bit float samples are not supported".into(),
            });
        }
        let data = reader
            .channel_data(c)
            .map_err(|e| i2(&format!("channel '{}'", c.name), e))?;
        out.push(RawChannel {
            name: c.name.trim().to_string(),
            unit: c.unit.trim().to_string(),
            values: data.iter().map(|s| decode(s, c)).collect(),
            rate_hz: Some(c.sample_rate as f64),
        });
    }
    let (beacons_s, details) = read_ldx(&path.with_extension("ldx"))?.unwrap_or_default();
    let meta = LogMeta {
        beacons_s,
        format: "MoTeC ld".into(),
        venue: header.venue.trim().to_string(),
        vehicle: header.vehicleid.trim().to_string(),
        driver: header.driver.trim().to_string(),
        session: header.session.trim().to_string(),
        comment: header.short_comment.trim().to_string(),
        date: parse_date(&header.date_string),
        time_of_day_s: parse_time_of_day(&header.time_string),
        header: details,
    };
    Ok(RawLog {
        path: path.to_path_buf(),
        meta,
        channels: out,
    })
}

/// A `.ldx` sidecar: beacon times (s) and the details' id/value pairs.
pub type Ldx = (Vec<f64>, std::collections::BTreeMap<String, String>);

/// Largest `.ldx` read (bytes).
const MAX_LDX_BYTES: u64 = 64 << 20;

/// Reads a `.ld` log's `.ldx` sidecar when there is one: the beacon
/// markers' times (`<Marker Time="µs"/>`, seconds from the log's start,
/// sorted) and the `<Details><String Id=.. Value=../>` pairs. A sidecar
/// that is not well-formed XML, or a marker time that is not a number, is
/// an error naming it.
pub(crate) fn read_ldx(path: &Path) -> Result<Option<Ldx>, ImportError> {
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(None);
    };
    if !meta.is_file() {
        return Err(ImportError::log(
            path,
            "file",
            "is not a regular file (a device, FIFO or folder)",
        ));
    }
    if meta.len() > MAX_LDX_BYTES {
        return Err(ImportError::log(
            path,
            "file",
            format!("{} bytes is over the 64 MiB limit", meta.len()),
        ));
    }
    let text = std::fs::read_to_string(path).map_err(|e| ImportError::io(path, e))?;
    let doc = roxmltree::Document::parse(&text)
        .map_err(|e| ImportError::log(path, "XML", e.to_string()))?;
    let mut beacons = Vec::new();
    let mut details = std::collections::BTreeMap::new();
    for node in doc.descendants() {
        match node.tag_name().name() {
            "Marker" => {
                let t = node.attribute("Time").ok_or_else(|| {
                    ImportError::log(
                        path,
                        format!("Marker at line {}", doc.text_pos_at(node.range().start).row),
                        "no Time",
                    )
                })?;
                let us: f64 = t
                    .trim()
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| {
                        ImportError::log(
                            path,
                            format!("Marker at line {}", doc.text_pos_at(node.range().start).row),
                            format!("Time '{t}' is not a time in microseconds"),
                        )
                    })?;
                beacons.push(us / 1e6);
            }
            "String" => {
                if let (Some(id), Some(v)) = (node.attribute("Id"), node.attribute("Value")) {
                    details.insert(id.to_string(), v.to_string());
                }
            }
            _ => {}
        }
    }
    beacons.sort_by(f64::total_cmp);
    Ok(Some((beacons, details)))
}

/// One channel to write into a `.ld` file: values are stored as 32-bit
/// integers with `dec_places` decimals (as loggers store them).
pub struct LdChannel<'a> {
    pub name: &'a str,
    pub short_name: &'a str,
    pub unit: &'a str,
    pub rate_hz: u16,
    pub dec_places: i16,
    pub values: &'a [f64],
}

/// Header fields of a written `.ld` file.
pub struct LdHeader<'a> {
    pub date: &'a str,
    pub time: &'a str,
    pub driver: &'a str,
    pub vehicle: &'a str,
    pub venue: &'a str,
    pub session: &'a str,
    pub comment: &'a str,
}

/// Writes a `.ld` file with the crate's writer (used by the simulator's
/// logger export), atomically.
pub(crate) fn write_ld(
    path: &Path,
    header: &LdHeader,
    channels: &[LdChannel],
) -> Result<(), ImportError> {
    // The crate's writer lays channel metadata from byte 0x3448 on.
    const META_AT: u32 = 0x3448;
    let hdr = motec_i2::Header {
        channel_meta_ptr: META_AT,
        channel_data_ptr: META_AT + channels.len() as u32 * ENTRY as u32,
        event_ptr: 0x06E2,
        device_serial: 0,
        device_type: "ADL".into(),
        device_version: 420,
        num_channels: channels.len() as u32,
        date_string: header.date.into(),
        time_string: header.time.into(),
        driver: header.driver.into(),
        vehicleid: header.vehicle.into(),
        venue: header.venue.into(),
        session: header.session.into(),
        short_comment: header.comment.into(),
    };
    let mut buf = Cursor::new(Vec::new());
    let mut w = motec_i2::LDWriter::new(&mut buf, hdr);
    for c in channels {
        let scale = 10f64.powi(c.dec_places as i32);
        let meta = ChannelMetadata {
            prev_addr: 0,
            next_addr: 0,
            data_addr: 0,
            data_count: 0,
            datatype: Datatype::I32,
            sample_rate: c.rate_hz,
            offset: 0,
            mul: 1,
            scale: 1,
            dec_places: c.dec_places,
            name: c.name.into(),
            short_name: c.short_name.into(),
            unit: c.unit.into(),
        };
        let samples = c
            .values
            .iter()
            .map(
                |v| Sample::I32((v * scale).round().clamp(i32::MIN as f64, i32::MAX as f64) as i32),
            )
            .collect();
        w = w.with_channel(meta, samples);
    }
    w.write()
        .map_err(|e| ImportError::log(path, "write", e.to_string()))?;
    crate::atomic::write_bytes(path, buf.get_ref()).map_err(|e| ImportError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_to_the_stored_precision_and_damage_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("run.ld");
        let speed: Vec<f64> = (0..50).map(|i| 100.0 + 0.123_456 * i as f64).collect();
        let temp: Vec<f64> = (0..10).map(|i| 80.0 + 0.37 * i as f64).collect();
        let header = LdHeader {
            date: "02/03/2026",
            time: "14:05:00",
            driver: "A. Driver",
            vehicle: "car1",
            venue: "Valle Rossa",
            session: "R1",
            comment: "test",
        };
        write_ld(
            &p,
            &header,
            &[
                LdChannel {
                    name: "Ground Speed",
                    short_name: "Gnd Spd",
                    unit: "km/h",
                    rate_hz: 50,
                    dec_places: 3,
                    values: &speed,
                },
                LdChannel {
                    name: "Tyre Temp FL Centre",
                    short_name: "TT FL C",
                    unit: "C",
                    rate_hz: 10,
                    dec_places: 1,
                    values: &temp,
                },
            ],
        )
        .unwrap();
        let log = read_ld(&p).unwrap();
        assert_eq!(log.meta.venue, "Valle Rossa");
        assert_eq!(log.meta.date.as_deref(), Some("2026-03-02"));
        assert_eq!(log.meta.time_of_day_s, Some(14.0 * 3600.0 + 300.0));
        assert_eq!(log.channels.len(), 2);
        assert_eq!(log.channels[0].rate_hz, Some(50.0));
        assert_eq!(log.channels[1].unit, "C");
        for (a, b) in log.channels[0].values.iter().zip(&speed) {
            assert!((a - b).abs() <= 0.5e-3 + 1e-9, "{a} vs {b}");
        }
        for (a, b) in log.channels[1].values.iter().zip(&temp) {
            assert!((a - b).abs() <= 0.05 + 1e-9, "{a} vs {b}");
        }

        // A cycle in the channel list: the crate would loop for ever.
        let mut bytes = std::fs::read(&p).unwrap();
        let second = 0x3448 + ENTRY;
        bytes[second + 4..second + 8].copy_from_slice(&0x3448u32.to_le_bytes());
        let bad = dir.path().join("loop.ld");
        std::fs::write(&bad, &bytes).unwrap();
        let e = read_ld(&bad).unwrap_err().to_string();
        assert!(e.contains("loop.ld") && e.contains("loops"), "{e}");
        // An unknown sample type: the crate would panic.
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[0x3448 + 18..0x3448 + 20].copy_from_slice(&9u16.to_le_bytes());
        std::fs::write(&bad, &bytes).unwrap();
        let e = read_ld(&bad).unwrap_err().to_string();
        assert!(e.contains("unknown sample type 9"), "{e}");
        // Truncated in the data.
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&bad, &bytes[..bytes.len() - 8]).unwrap();
        let e = read_ld(&bad).unwrap_err().to_string();
        assert!(e.contains("past the end"), "{e}");
    }
}
