//! Season presets: which tracks, events, cars and runs a season has.

use super::compound::{CompoundModel, catalogue};
use super::track::{RoadParams, TrackDef};
use super::vehicle::CarParams;
use crate::calendar::{civil_from_days, days_from_civil};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A season layout of the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preset {
    /// 2 tracks, 2 events, 1 car, 2 short runs each: for tests and quick checks.
    Tiny,
    /// 8 tracks, 10 events, 2 cars, 320 tire-runs at 20 Hz: under a minute.
    Demo,
    /// 12 tracks, 24 events × scale, 3 cars, 6 runs each at 200 Hz: ~20 GB at scale 1.
    Season,
}

#[derive(Debug, Clone)]
pub struct EventPlan {
    pub id: String,
    pub track: usize,
    pub date: String,
    pub air_c: f64,
    pub track_c: f64,
}

#[derive(Debug, Clone)]
pub struct RunPlan {
    pub id: String,
    pub event: usize,
    pub car: usize,
    pub compound: usize,
    pub distance_m: f64,
    /// Share of the available grip the driver uses.
    pub pace: f64,
    pub cold_pressure_pa: [f64; 4],
    pub seed: u64,
    /// Start of the run (ns since the Unix epoch).
    pub start_ns: u64,
}

/// Everything a season will contain, before any physics runs.
#[derive(Debug, Clone)]
pub struct Plan {
    pub name: String,
    pub tracks: Vec<TrackDef>,
    pub compounds: Vec<CompoundModel>,
    pub cars: Vec<CarParams>,
    pub events: Vec<EventPlan>,
    pub runs: Vec<RunPlan>,
    pub rate_hz: f64,
    pub profile_samples: usize,
    pub profile_dx_mm: f64,
    pub locations_per_track: usize,
}

/// The twelve tracks of the catalogue (the demo uses the first eight).
pub fn track_catalogue() -> Vec<TrackDef> {
    // (id, name, length m, corners, grip, hidden abrasiveness, H, rms mm, roll-off mm, skew, kurt)
    #[allow(clippy::type_complexity)] // a table: one tuple per track reads best
    let rows: [(&str, &str, f64, usize, f64, f64, f64, f64, f64, f64, f64); 12] = [
        (
            "valle-rossa",
            "Valle Rossa",
            5200.0,
            11,
            1.00,
            1.02,
            0.82,
            0.45,
            25.0,
            -0.07,
            0.02,
        ),
        (
            "nordkamm",
            "Nordkamm Ring",
            4300.0,
            14,
            0.97,
            0.97,
            0.74,
            0.62,
            32.0,
            -0.20,
            0.06,
        ),
        (
            "baie-du-sud",
            "Baie du Sud",
            5800.0,
            12,
            1.03,
            1.04,
            0.88,
            0.30,
            18.0,
            -0.01,
            0.00,
        ),
        (
            "sierra-azul",
            "Sierra Azul",
            4700.0,
            15,
            0.99,
            1.00,
            0.70,
            0.55,
            28.0,
            -0.14,
            0.10,
        ),
        (
            "kiefernring",
            "Kiefernring",
            3900.0,
            10,
            1.01,
            0.98,
            0.79,
            0.38,
            22.0,
            -0.04,
            0.04,
        ),
        (
            "porto-vento",
            "Porto Vento",
            6300.0,
            13,
            0.96,
            1.03,
            0.68,
            0.72,
            36.0,
            -0.23,
            0.08,
        ),
        (
            "lakeside",
            "Lakeside Park",
            4000.0,
            9,
            1.02,
            1.01,
            0.85,
            0.34,
            20.0,
            -0.10,
            0.12,
        ),
        (
            "desert-loop",
            "Desert Loop",
            5500.0,
            12,
            0.98,
            0.99,
            0.76,
            0.50,
            30.0,
            -0.17,
            0.03,
        ),
        (
            "hafen",
            "Hafen Circuit",
            4800.0,
            16,
            1.00,
            1.00,
            0.72,
            0.42,
            26.0,
            -0.11,
            0.07,
        ),
        (
            "monte-leone",
            "Monte Leone",
            5900.0,
            11,
            0.99,
            1.02,
            0.80,
            0.58,
            34.0,
            -0.21,
            0.02,
        ),
        (
            "riverside",
            "Riverside",
            4400.0,
            12,
            1.01,
            0.98,
            0.87,
            0.28,
            17.0,
            -0.03,
            0.09,
        ),
        (
            "highland",
            "Highland Raceway",
            5100.0,
            14,
            0.97,
            1.01,
            0.66,
            0.66,
            38.0,
            -0.18,
            0.11,
        ),
    ];
    rows.iter()
        .enumerate()
        .map(|(i, r)| TrackDef {
            id: r.0.into(),
            name: r.1.into(),
            seed: 1000 + i as u64,
            length_target_m: r.2,
            corners: r.3,
            grip: r.4,
            hidden_abrasiveness: r.5,
            road: RoadParams {
                hurst: r.6,
                rms_mm: r.7,
                rolloff_mm: r.8,
                cutoff_mm: 0.04,
                skew_coef: r.9,
                kurt_coef: r.10,
            },
        })
        .collect()
}

/// The most tracks a season may have (`SimOptions::tracks`).
pub const MAX_TRACKS: usize = 64;

/// Most events of a season preset (`--scale` up to 41.6): the calendar and
/// the plan are sized from it, so `--scale 1e9` is refused instead of
/// asking for terabytes.
pub const MAX_EVENTS: usize = 1000;

/// The first `n` tracks of a season: the catalogue's twelve, then tracks
/// generated from their index alone (`generated_track`), so that track 13
/// is the same in every season that has it.
pub fn tracks(n: usize) -> Vec<TrackDef> {
    let mut tracks = track_catalogue();
    tracks.truncate(n);
    let first = tracks.len();
    tracks.extend((first..n).map(generated_track));
    tracks
}

/// Track `index` (0-based) beyond the catalogue: each parameter drawn
/// uniformly from the catalogue's own range, from a generator seeded by the
/// index (the road's seed follows the catalogue's numbering, 1000 + index).
fn generated_track(index: usize) -> TrackDef {
    let mut rng = ChaCha8Rng::seed_from_u64(0x7472_6163_6b00 + index as u64);
    let mut within = |lo: f64, hi: f64| rng.random_range(lo..=hi);
    let length_target_m = (within(3900.0, 6300.0) / 100.0).round() * 100.0;
    let corners = within(9.0, 16.0).round() as usize;
    let grip = within(0.96, 1.03);
    let hidden_abrasiveness = within(0.97, 1.04);
    let road = RoadParams {
        hurst: within(0.66, 0.88),
        rms_mm: within(0.28, 0.72),
        rolloff_mm: within(17.0, 38.0),
        cutoff_mm: 0.04,
        skew_coef: within(-0.23, -0.01),
        kurt_coef: within(0.0, 0.12),
    };
    TrackDef {
        id: format!("track-{}", index + 1),
        name: format!("Track {}", index + 1),
        seed: 1000 + index as u64,
        length_target_m,
        corners,
        grip,
        hidden_abrasiveness,
        road,
    }
}

impl Plan {
    /// Builds the plan of a preset. `scale` multiplies the number of events
    /// (season preset); `n_tracks` overrides the preset's number of tracks
    /// (`tracks`) and `rate_hz` its sample rate.
    pub fn new(
        preset: Preset,
        scale: f64,
        n_tracks: Option<usize>,
        seed: u64,
        rate_hz: Option<f64>,
    ) -> Plan {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7469_7265_7765_6172);
        let (name, preset_tracks, n_events, n_cars, runs_per_car, rate, dist) = match preset {
            Preset::Tiny => ("tiny", 2, 2, 1, 2, 20.0, (6e3, 12e3)),
            Preset::Demo => ("demo", 8, 10, 2, 4, 20.0, (30e3, 110e3)),
            Preset::Season => {
                let events = ((24.0 * scale).round() as usize).max(1);
                ("season", 12, events, 3, 6, 200.0, (30e3, 110e3))
            }
        };
        let n_tracks = n_tracks.unwrap_or(preset_tracks);
        let tracks = self::tracks(n_tracks);
        let cars: Vec<CarParams> = (0..n_cars)
            .map(|i| {
                CarParams::single_seater(
                    &format!("car{}", i + 1),
                    &format!("Car #{}", i + 1),
                    i as f64 - 0.5 * (n_cars - 1) as f64,
                )
            })
            .collect();
        let compounds = catalogue();
        let season_start = days_from_civil(2026, 3, 1);
        let events: Vec<EventPlan> = (0..n_events)
            .map(|e| {
                // Every track once, then again in a different order.
                let track = if e < n_tracks {
                    e
                } else {
                    (e * 5 + 3) % n_tracks
                };
                let day =
                    season_start + (e as i64 * 240) / n_events as i64 + rng.random_range(0..3);
                let (y, m, d) = civil_from_days(day);
                let air_c: f64 = rng.random_range(12.0..36.0);
                EventPlan {
                    id: format!("E{:02}-{}", e + 1, tracks[track].id),
                    track,
                    date: format!("{y:04}-{m:02}-{d:02}"),
                    air_c: (air_c * 10.0).round() / 10.0,
                    track_c: ((air_c + rng.random_range(4.0..26.0)) * 10.0).round() / 10.0,
                }
            })
            .collect();
        let nominations: Vec<usize> = events.iter().map(|_| rng.random_range(0..3)).collect();
        let mut runs = Vec::new();
        for (ei, ev) in events.iter().enumerate() {
            let day = {
                let p: Vec<i64> = ev
                    .date
                    .split('-')
                    .map(|s| s.parse().expect("we wrote it"))
                    .collect();
                days_from_civil(p[0], p[1], p[2])
            };
            for (car, car_params) in cars.iter().enumerate() {
                for r in 0..runs_per_car {
                    // The supplier nominates one compound per event; a fifth of the
                    // runs try a neighbouring one.
                    let nominated = nominations[ei];
                    let compound = if rng.random_bool(0.8) {
                        nominated
                    } else if nominated == 0 || (nominated == 1 && rng.random_bool(0.5)) {
                        nominated + 1
                    } else {
                        nominated - 1
                    };
                    // Stint length by compound: softer compounds run shorter.
                    let longest = dist.0 + (dist.1 - dist.0) * [0.5, 0.75, 1.0][compound];
                    let distance_m: f64 = rng.random_range(dist.0..longest);
                    let front: f64 = rng.random_range(70e3..85e3);
                    let rear: f64 = rng.random_range(68e3..82e3);
                    let jitter = |rng: &mut ChaCha8Rng| rng.random_range(-500.0..500.0);
                    let hour = 9 + r as u64 * 2 + car as u64;
                    runs.push(RunPlan {
                        id: format!("{}-{}-R{}", ev.id, car_params.id, r + 1),
                        event: ei,
                        car,
                        compound,
                        distance_m: distance_m.round(),
                        pace: rng.random_range(0.82..0.94),
                        cold_pressure_pa: [
                            (front + jitter(&mut rng)).round(),
                            (front + jitter(&mut rng)).round(),
                            (rear + jitter(&mut rng)).round(),
                            (rear + jitter(&mut rng)).round(),
                        ],
                        seed: rng.random(),
                        start_ns: (day as u64 * 86_400 + hour * 3600) * 1_000_000_000,
                    });
                }
            }
        }
        Plan {
            name: name.into(),
            tracks,
            compounds,
            cars,
            events,
            runs,
            rate_hz: rate_hz.unwrap_or(rate),
            profile_samples: if preset == Preset::Tiny {
                1 << 12
            } else {
                1 << 14
            },
            profile_dx_mm: 0.01,
            locations_per_track: if preset == Preset::Tiny { 2 } else { 6 },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_has_enough_observations_from_separate_events() {
        let p = Plan::new(Preset::Demo, 1.0, None, 7, None);
        assert!(p.runs.len() * 4 >= 280);
        assert_eq!(p.tracks.len(), 8);
        assert!(p.events.len() >= 10);
    }

    /// Generated tracks: the catalogue's first, then new ones the same in
    /// every season, each parameter inside the catalogue's range, and each
    /// event of a season with as many events as tracks on its own track.
    #[test]
    fn more_tracks_than_the_catalogue() {
        let catalogue = track_catalogue();
        let t = tracks(24);
        assert_eq!(t.len(), 24);
        assert_eq!(
            t[..12].iter().map(|t| &t.id).collect::<Vec<_>>(),
            catalogue.iter().map(|t| &t.id).collect::<Vec<_>>()
        );
        let ids: std::collections::BTreeSet<&str> = t.iter().map(|t| t.id.as_str()).collect();
        assert_eq!(ids.len(), 24, "track ids are unique");
        let range = |f: fn(&TrackDef) -> f64| {
            catalogue
                .iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        let params: [fn(&TrackDef) -> f64; 9] = [
            |t| t.length_target_m,
            |t| t.corners as f64,
            |t| t.grip,
            |t| t.hidden_abrasiveness,
            |t| t.road.hurst,
            |t| t.road.rms_mm,
            |t| t.road.rolloff_mm,
            |t| t.road.skew_coef,
            |t| t.road.kurt_coef,
        ];
        for f in params {
            let (lo, hi) = range(f);
            for g in &t[12..] {
                assert!(
                    (lo..=hi).contains(&f(g)),
                    "{}: {} outside {lo}..{hi}",
                    g.id,
                    f(g)
                );
            }
            // Not one value for every generated track.
            assert!(t[12..].iter().any(|g| f(g) != f(&t[12])));
        }
        assert_eq!(t[12].id, "track-13");
        assert_eq!(t[12].seed, 1012);
        assert_eq!(format!("{:?}", tracks(13)[12]), format!("{:?}", t[12]));

        let p = Plan::new(Preset::Season, 1.0, Some(24), 3, None);
        assert_eq!(p.tracks.len(), 24);
        let mut visited: Vec<usize> = p.events.iter().map(|e| e.track).collect();
        visited.sort();
        assert_eq!(visited, (0..24).collect::<Vec<_>>());
        assert_eq!(
            Plan::new(Preset::Season, 0.5, None, 3, None).tracks.len(),
            12
        );
    }
}
