//! Putting a log's channels on one time base (`docs/import.md`, "Time
//! base"): a table keeps its own rows (a row's time must sit on the grid of
//! the sample period; a gap is a dropout); a log whose channels have their
//! own rates (`.ld`) is interpolated linearly onto the fastest mapped rate.

use super::channel_map::{Mapped, Mapping, Quantity};
use super::error::ImportError;
use super::log::RawLog;
use crate::Wheel;
use std::collections::BTreeMap;

/// Samples on one grid: sample `i` is at `t0_s + index[i] / rate_hz`.
#[derive(Debug, Clone, Default)]
pub struct Aligned {
    pub rate_hz: f64,
    pub t0_s: f64,
    pub index: Vec<u64>,
    /// Every mapped quantity in the archive's units, one value per sample.
    pub series: BTreeMap<(Quantity, Option<Wheel>), Vec<f64>>,
    /// Grid points dropped because a mapped channel had no value there.
    pub dropped: u64,
    /// The log's channel names and the names the map tried per quantity
    /// (for errors that name what is missing).
    pub source_names: Vec<String>,
    pub tried: BTreeMap<Quantity, Vec<String>>,
    /// The dimension each wheel's speed was given in (linear or angular).
    pub wheel_speed_dimension: [Option<super::units::Dimension>; 4],
}

impl Aligned {
    pub fn get(&self, q: Quantity, corner: Option<Wheel>) -> Option<&[f64]> {
        self.series.get(&(q, corner)).map(Vec::as_slice)
    }
    pub fn len(&self) -> usize {
        self.index.len()
    }
}

/// The largest rate accepted (Hz): the archive's limit.
const MAX_RATE_HZ: f64 = 1000.0;

fn mean_of_zones(log: &RawLog, m: &Mapped, at: impl Fn(&[f64], Option<f64>) -> f64) -> f64 {
    let (mut sum, mut n) = (0.0, 0);
    for &s in &m.sources {
        let c = &log.channels[s];
        let v = at(&c.values, c.rate_hz);
        if v.is_finite() {
            sum += v;
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        m.conversion.apply(sum / n as f64)
    }
}

/// Aligns the mapped channels. `rate_hz` overrides the rate a `.ld` log is
/// interpolated to.
pub(crate) fn align(
    log: &RawLog,
    mapping: &Mapping,
    rate_hz: Option<f64>,
) -> Result<Aligned, ImportError> {
    let mapped: Vec<&Mapped> = mapping
        .mapped
        .iter()
        .filter(|m| m.quantity != Quantity::Time)
        .collect();
    let mut out = Aligned {
        source_names: mapping.source_names.clone(),
        tried: mapping.tried.clone(),
        ..Aligned::default()
    };
    for w in Wheel::ALL {
        out.wheel_speed_dimension[w.index()] = mapping
            .get(Quantity::WheelSpeed, Some(w))
            .map(|m| m.conversion.dimension);
    }
    if log.tabular() {
        align_rows(log, mapping, &mapped, rate_hz, &mut out)?;
    } else {
        resample_channels(log, &mapped, rate_hz, &mut out)?;
    }
    Ok(out)
}

/// A table's rows on the grid of its time column: each row's time a whole
/// number of periods from the first (the rate the median step's, or
/// `rate_hz`); rows where a mapped quantity has no value are dropped.
fn align_rows(
    log: &RawLog,
    mapping: &Mapping,
    mapped: &[&Mapped],
    rate_hz: Option<f64>,
    out: &mut Aligned,
) -> Result<(), ImportError> {
    let path = &log.path;
    let time = mapping
        .get(Quantity::Time, None)
        .ok_or_else(|| ImportError::Missing {
            path: path.clone(),
            quantity: "time".into(),
            tried: mapping
                .tried
                .get(&Quantity::Time)
                .map_or("[channels.time] has no names".into(), |t| t.join(", ")),
            available: log.names().join(", "),
        })?;
    let tc = &log.channels[time.sources[0]];
    let t: Vec<f64> = tc
        .values
        .iter()
        .map(|v| time.conversion.apply(*v))
        .collect();
    let bad = |row: usize, what: String| ImportError::Channel {
        path: path.clone(),
        channel: tc.name.clone(),
        what: format!("sample {row}: {what}"),
    };
    if let Some(i) = t.iter().position(|v| !v.is_finite()) {
        return Err(bad(i, "no time".into()));
    }
    if let Some(i) = (1..t.len()).find(|&i| t[i] <= t[i - 1]) {
        return Err(bad(
            i,
            format!(
                "time {} s is not after the previous {} s (non-monotonic)",
                t[i],
                t[i - 1]
            ),
        ));
    }
    if t.len() < 2 {
        return Err(ImportError::log(path, "data", "fewer than two samples"));
    }
    out.rate_hz = rows_rate_hz(&t, rate_hz);
    if !(out.rate_hz.is_finite() && out.rate_hz > 0.0 && out.rate_hz <= MAX_RATE_HZ * 1.001) {
        return Err(bad(
            0,
            format!(
                "sample rate {} Hz is outside (0, 1000]",
                super::shown(out.rate_hz)
            ),
        ));
    }
    let period = 1.0 / out.rate_hz;
    out.t0_s = t[0];
    let mut index = Vec::with_capacity(t.len());
    for (i, &ti) in t.iter().enumerate() {
        let x = (ti - t[0]) / period;
        let k = x.round();
        if (x - k).abs() > 0.25 {
            return Err(bad(
                i,
                format!(
                    "time {ti} s is off the {:.6} s sample grid by {:.0} % of a period \
                     (mixed rates? export on one rate, or give --rate)",
                    period,
                    (x - k).abs() * 100.0
                ),
            ));
        }
        index.push(k as u64);
    }
    let mut keep = vec![true; t.len()];
    for m in mapped {
        let v: Vec<f64> = (0..t.len())
            .map(|i| mean_of_zones(log, m, |vals, _| vals[i]))
            .collect();
        for (k, x) in keep.iter_mut().zip(&v) {
            *k &= x.is_finite();
        }
        out.series.insert((m.quantity, m.corner), v);
    }
    out.index = index;
    filter(out, &keep);
    Ok(())
}

/// The rate (Hz) of rows at times `t` (s): `rate_hz`, else one over the
/// median step; within 1 ppm of a whole number of Hz, that number (times
/// written with 3 decimals give 19.999999999 Hz).
fn rows_rate_hz(t: &[f64], rate_hz: Option<f64>) -> f64 {
    let period = match rate_hz {
        Some(r) => 1.0 / r,
        None => {
            let mut dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
            dt.sort_by(f64::total_cmp);
            dt[dt.len() / 2]
        }
    };
    let r = 1.0 / period;
    if (r - r.round()).abs() < 1e-6 * r {
        r.round()
    } else {
        r
    }
}

/// Channels of their own rates (a `.ld` log) interpolated to one grid:
/// `rate_hz`, else the fastest mapped channel's rate, over the shortest
/// mapped channel; grid points where a mapped quantity has no value are
/// dropped.
fn resample_channels(
    log: &RawLog,
    mapped: &[&Mapped],
    rate_hz: Option<f64>,
    out: &mut Aligned,
) -> Result<(), ImportError> {
    let path = &log.path;
    let rate = match rate_hz {
        Some(r) => r,
        None => mapped
            .iter()
            .flat_map(|m| {
                m.sources
                    .iter()
                    .map(|&s| log.channels[s].rate_hz.unwrap_or(0.0))
            })
            .fold(0.0, f64::max),
    };
    if !(rate > 0.0 && rate <= MAX_RATE_HZ) {
        return Err(ImportError::log(
            path,
            "channels",
            format!("sample rate {} Hz is outside (0, 1000]", super::shown(rate)),
        ));
    }
    let duration = mapped
        .iter()
        .flat_map(|m| {
            m.sources.iter().map(|&s| {
                let c = &log.channels[s];
                (c.values.len().saturating_sub(1)) as f64 / c.rate_hz.unwrap_or(1.0)
            })
        })
        .fold(f64::INFINITY, f64::min);
    if !duration.is_finite() || duration <= 0.0 {
        return Err(ImportError::log(
            path,
            "channels",
            "no mapped channel has two samples",
        ));
    }
    let n = (duration * rate).floor() as u64 + 1;
    out.rate_hz = rate;
    out.index = (0..n).collect();
    let mut keep = vec![true; n as usize];
    for m in mapped {
        let v: Vec<f64> = (0..n)
            .map(|k| {
                mean_of_zones(log, m, |vals, r| {
                    let x = k as f64 / rate * r.unwrap_or(rate);
                    let i = (x.floor() as usize).min(vals.len() - 1);
                    let j = (i + 1).min(vals.len() - 1);
                    let w = x - i as f64;
                    vals[i] * (1.0 - w) + vals[j] * w
                })
            })
            .collect();
        for (k, x) in keep.iter_mut().zip(&v) {
            *k &= x.is_finite();
        }
        out.series.insert((m.quantity, m.corner), v);
    }
    filter(out, &keep);
    Ok(())
}

fn filter(out: &mut Aligned, keep: &[bool]) {
    out.dropped = keep.iter().filter(|k| !**k).count() as u64;
    if out.dropped == 0 {
        return;
    }
    let pick = |v: &Vec<f64>| {
        v.iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(x, _)| *x)
            .collect::<Vec<f64>>()
    };
    out.index = out
        .index
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(x, _)| *x)
        .collect();
    for v in out.series.values_mut() {
        *v = pick(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::channel_map::ChannelMap;
    use crate::import::log::{LogMeta, RawChannel};
    use std::path::{Path, PathBuf};

    fn log(chans: Vec<(&str, &str, Vec<f64>, Option<f64>)>) -> RawLog {
        RawLog {
            path: PathBuf::from("x.log"),
            meta: LogMeta::default(),
            channels: chans
                .into_iter()
                .map(|(n, u, v, r)| RawChannel {
                    name: n.into(),
                    unit: u.into(),
                    values: v,
                    rate_hz: r,
                })
                .collect(),
        }
    }

    fn run(l: &RawLog) -> Result<Aligned, ImportError> {
        let m = ChannelMap::default_map()
            .map(Path::new("x.log"), &l.names(), &l.units())
            .unwrap();
        align(l, &m, None)
    }

    #[test]
    fn table_rows_keep_their_grid_and_gaps_are_dropouts() {
        let l = log(vec![
            ("Time", "s", vec![0.0, 0.1, 0.2, 0.5, 0.6], None),
            (
                "Ground Speed",
                "km/h",
                vec![36.0, 36.0, f64::NAN, 72.0, 72.0],
                None,
            ),
        ]);
        let a = run(&l).unwrap();
        assert!((a.rate_hz - 10.0).abs() < 1e-9);
        assert_eq!(
            a.index,
            [0, 1, 5, 6],
            "the NaN row is dropped, the gap kept"
        );
        assert_eq!(a.dropped, 1);
        assert_eq!(
            a.get(Quantity::GroundSpeed, None).unwrap(),
            [10.0, 10.0, 20.0, 20.0]
        );
    }

    #[test]
    fn bad_time_columns_are_refused_by_name() {
        let e = run(&log(vec![
            ("Time", "s", vec![0.0, 0.1, 0.05], None),
            ("Speed", "m/s", vec![1.0; 3], None),
        ]))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("'Time'") && e.contains("non-monotonic") && e.contains("sample 2"),
            "{e}"
        );
        let e = run(&log(vec![
            ("Time", "s", vec![0.0, 0.1, 0.2, 0.3, 0.35, 0.4], None),
            ("Speed", "m/s", vec![1.0; 6], None),
        ]))
        .unwrap_err()
        .to_string();
        assert!(e.contains("mixed rates") && e.contains("sample 4"), "{e}");
    }

    #[test]
    fn channels_at_their_own_rates_are_interpolated_onto_the_fastest() {
        // 10 Hz ramp and a 2 Hz ramp of the same slope: both read t·slope at 10 Hz.
        let l = log(vec![
            (
                "Ground Speed",
                "m/s",
                (0..11).map(|i| i as f64 * 0.1).collect(),
                Some(10.0),
            ),
            (
                "Yaw Rate",
                "rad/s",
                (0..3).map(|i| i as f64 * 0.5).collect(),
                Some(2.0),
            ),
        ]);
        let a = run(&l).unwrap();
        assert_eq!(a.rate_hz, 10.0);
        assert_eq!(a.len(), 11);
        let yaw = a.get(Quantity::YawRate, None).unwrap();
        for (k, y) in yaw.iter().enumerate() {
            assert!((y - k as f64 * 0.1).abs() < 1e-12, "{k}: {y}");
        }
    }
}
