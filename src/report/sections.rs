//! The report's sections, one function each, in page order.

use super::figure::{self, Axes, Bar, Points, Segment, Whisker};
use super::html::{csv_link, escape, figure as fig, num, table};
use super::{Inputs, ReportError, Section};
use crate::Axle;
use crate::kpi::KpiRow;
use crate::model::interval::{Coverage, IntervalLevel};
use crate::model::saved::SavedModel;
use serde_json::Value;
use std::collections::BTreeSet;

/// A row whose wear is measured, not censored: readings present and the
/// tread not worn through anywhere (there the wear is only a lower bound),
/// the rows the models are fitted on.
fn measured(r: &KpiRow) -> bool {
    r.wear_mean_pct.is_finite() && r.worn_through_readings <= 0.0
}

fn missing(text: &str) -> String {
    format!("<p class=\"missing\">{}</p>\n", escape(text))
}

/// The season section: what the season holds, and what was left out and why.
pub(super) fn season(inputs: &Inputs) -> Section {
    let rows = &inputs.rows;
    let count = |f: &dyn Fn(&KpiRow) -> &str| rows.iter().map(f).collect::<BTreeSet<_>>().len();
    let mut html = table(
        &["", "count"],
        &[
            vec!["events".into(), count(&|r| r.event.as_str()).to_string()],
            vec!["tracks".into(), count(&|r| r.track.as_str()).to_string()],
            vec!["cars".into(), count(&|r| r.car.as_str()).to_string()],
            vec![
                "compounds".into(),
                count(&|r| r.compound.as_str()).to_string(),
            ],
            vec!["runs".into(), count(&|r| r.run.as_str()).to_string()],
            vec!["tire-runs (KPI rows)".into(), rows.len().to_string()],
            vec![
                "tire-runs with wear readings".into(),
                rows.iter()
                    .filter(|r| r.wear_mean_pct.is_finite())
                    .count()
                    .to_string(),
            ],
        ],
    );
    let (wear, figures) = wear_by_event(rows);
    html += &wear;
    match &inputs.extraction {
        Some(report) => {
            // `extract`'s skipped runs, or `process`'s failed ones (which
            // may keep their rows from an earlier commit).
            let process = !report["skipped"].is_array();
            let list = if process {
                &report["failed"]
            } else {
                &report["skipped"]
            };
            let failed: Vec<Vec<String>> = list
                .as_array()
                .into_iter()
                .flatten()
                .map(|s| {
                    let mut row = vec![
                        s["run"].as_str().unwrap_or("").to_string(),
                        s["reason"].as_str().unwrap_or("").to_string(),
                    ];
                    if process {
                        let kept = s["kept"].as_bool().unwrap_or(false);
                        row.push(if kept { "the last commit's" } else { "none" }.into());
                    }
                    row
                })
                .collect();
            let (title, columns): (&str, &[&str]) = if process {
                ("Failed runs", &["run", "reason", "rows in the dataset"])
            } else {
                ("Skipped runs", &["run", "reason"])
            };
            html += &format!(
                "<h3>{title} ({})</h3>\n{}",
                failed.len(),
                if failed.is_empty() {
                    "<p>None: every run of the manifest was extracted.</p>".to_string()
                } else {
                    table(columns, &failed)
                }
            );
        }
        None => html += &missing("kpis.report.json is missing: skipped runs unknown."),
    }
    if let Some(gap) = &inputs.gap {
        let censored: Vec<Vec<String>> = gap["censored"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|v| v.as_str())
            .map(|s| vec![s.to_string(), "tread worn through: wear censored".into()])
            .collect();
        html += &format!(
            "<h3>Censored tires ({})</h3>\n{}",
            censored.len(),
            if censored.is_empty() {
                "<p>None.</p>".to_string()
            } else {
                table(&["run/wheel", "reason"], &censored)
            }
        );
    }
    Section {
        title: "Season".into(),
        html,
        figures,
    }
}

/// Measured wear by event and axle: a table (tires, measured, mean, sample
/// standard deviation, least and most, worn through) and a figure of the
/// means with the least-to-most range as whiskers, with the number of
/// figures drawn. A worn-through tire's wear is only a lower bound: it is
/// counted apart, not averaged.
fn wear_by_event(rows: &[KpiRow]) -> (String, usize) {
    let mut groups: std::collections::BTreeMap<(&str, Axle), Vec<&KpiRow>> = Default::default();
    for r in rows {
        groups
            .entry((r.event.as_str(), r.axle))
            .or_default()
            .push(r);
    }
    if groups.is_empty() {
        return (String::new(), 0);
    }
    let events: Vec<&str> = groups
        .keys()
        .map(|k| k.0)
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut cells = Vec::new();
    let mut points = [Vec::new(), Vec::new()];
    let mut whiskers = Vec::new();
    for ((event, axle), tires) in &groups {
        let wear: Vec<f64> = tires
            .iter()
            .filter(|r| measured(r))
            .map(|r| r.wear_mean_pct)
            .collect();
        let worn = tires
            .iter()
            .filter(|r| r.worn_through_readings > 0.0)
            .count();
        let n = wear.len() as f64;
        let mean = wear.iter().sum::<f64>() / n;
        let sd = if wear.len() > 1 {
            (wear.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        } else {
            f64::NAN
        };
        let least = wear.iter().copied().fold(f64::INFINITY, f64::min);
        let most = wear.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let compounds: BTreeSet<&str> = tires.iter().map(|r| r.compound.as_str()).collect();
        cells.push(vec![
            event.to_string(),
            tires[0].track.clone(),
            compounds.into_iter().collect::<Vec<_>>().join(" "),
            axle.to_string(),
            tires.len().to_string(),
            wear.len().to_string(),
            num(mean, 2),
            num(sd, 2),
            num(least, 2),
            num(most, 2),
            worn.to_string(),
        ]);
        if !wear.is_empty() {
            // Front left of the event's place, rear right.
            let (side, offset) = match axle {
                Axle::Front => (0, -0.15),
                Axle::Rear => (1, 0.15),
            };
            let x = events.partition_point(|e| e < event) as f64 + 1.0 + offset;
            points[side].push((x, mean));
            whiskers.push(Whisker {
                color: side,
                x,
                y: (least, most),
            });
        }
    }
    let header = [
        "event",
        "track",
        "compounds",
        "axle",
        "tires",
        "measured",
        "mean wear (%)",
        "sd (%)",
        "least (%)",
        "most (%)",
        "worn through",
    ];
    let mut html = String::from("<h3>Wear by event</h3>\n");
    let [front, rear] = points;
    let svg = figure::scatter_with_whiskers(
        &Axes {
            title: "Measured wear by event",
            x: "event (1, 2, … in id order, as in the table)",
            y: "mean wear (%)",
        },
        &[
            Points {
                label: "front".into(),
                color: 0,
                xy: front,
                filled: true,
            },
            Points {
                label: "rear".into(),
                color: 1,
                xy: rear,
                filled: true,
            },
        ],
        &[],
        (&whiskers, f64::INFINITY),
        true,
    );
    let figures = match svg {
        Ok(svg) => {
            html += &fig(
                &svg,
                "Each event's mean measured wear per axle (front left of its place, rear \
right), the whisker from the least to the most worn tire; tires worn through are left out \
(their wear is only a lower bound) and counted in the table.",
                &csv_link("wear_by_event.csv", &header, &cells),
            );
            1
        }
        Err(e) => {
            html += &missing(&format!("The wear-by-event figure could not be drawn: {e}"));
            0
        }
    };
    html += &table(&header, &cells);
    (html, figures)
}

/// The curve of one track: the mean over its locations where they share the
/// x grid, else its first location's.
fn track_curve(inputs: &Inputs, track: &str, curve: &str) -> Vec<(f64, f64)> {
    let mut by_location: std::collections::BTreeMap<&str, Vec<(f64, f64)>> = Default::default();
    for p in inputs
        .road
        .iter()
        .filter(|p| p.track == track && p.curve == curve)
    {
        by_location
            .entry(p.location.as_str())
            .or_default()
            .push((p.x, p.y));
    }
    let mut curves = by_location.into_values();
    let Some(first) = curves.next() else {
        return Vec::new();
    };
    let rest: Vec<Vec<(f64, f64)>> = curves.collect();
    let same_grid = rest
        .iter()
        .all(|c| c.len() == first.len() && c.iter().zip(&first).all(|(a, b)| a.0 == b.0));
    if !same_grid {
        return first;
    }
    let k = 1.0 + rest.len() as f64;
    first
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| (x, (y + rest.iter().map(|c| c[i].1).sum::<f64>()) / k))
        .collect()
}

/// The fitted Hurst line of one track's curve: slope −(1 + 2H) on the PSD
/// over the wavenumbers of [`HURST_BAND_MM`](crate::kpi::road::HURST_BAND_MM),
/// 2H on the HDC over its lags (as `kpi::road` fits them), through the
/// curve's points in that band (least squares for the intercept in log-log).
fn hurst_line(inputs: &Inputs, track: &str, curve: &str, s: &Points) -> Option<Segment> {
    use crate::kpi::road::HURST_BAND_MM;
    let row = inputs.rows.iter().find(|r| r.track == track)?;
    let (lo, hi, slope) = if curve == "psd" {
        let tau = std::f64::consts::TAU;
        (
            tau / HURST_BAND_MM.1,
            tau / HURST_BAND_MM.0,
            -(1.0 + 2.0 * row.hurst),
        )
    } else {
        (
            HURST_BAND_MM.0 / 10.0,
            HURST_BAND_MM.1 / 10.0,
            2.0 * row.hurst_hdc,
        )
    };
    let logs: Vec<(f64, f64)> =
        s.xy.iter()
            .filter(|p| p.0 >= lo && p.0 <= hi && p.1 > 0.0)
            .map(|p| (p.0.ln(), p.1.ln()))
            .collect();
    if logs.len() < 2 || !slope.is_finite() {
        return None;
    }
    let n = logs.len() as f64;
    let a = logs.iter().map(|p| p.1 - slope * p.0).sum::<f64>() / n;
    let (x0, x1) = (
        logs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min),
        logs.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max),
    );
    Some(Segment {
        color: Some(s.color),
        from: (x0.exp(), (a + slope * x0).exp()),
        to: (x1.exp(), (a + slope * x1).exp()),
    })
}

/// The road section (table 3): the tracks' road texture, PSD and height-difference
/// correlation on log-log axes, and their roughness indices.
pub(super) fn road(inputs: &Inputs) -> Result<Section, ReportError> {
    let tracks = track_names(inputs);
    let mut html = String::new();
    let mut figures = 0;
    if inputs.road.is_empty() {
        html +=
            &missing("No kpis.road.parquet beside the KPI table: extract again to add the curves.");
    } else {
        for (curve, title, x, y, what) in [
            (
                "psd",
                "Road texture: power spectral density",
                "wavenumber q (rad/mm)",
                "C(q) (mm⁴)",
                "the 1-D power spectral density of the road profile (Welch), mean over the \
track's measured locations; the broad translucent lines have the fitted slope −(1 + 2H) \
over the band the Hurst exponent H (legend) is fitted on, wavelengths 0.1–5 mm",
            ),
            (
                "hdc",
                "Road texture: height-difference correlation",
                "lag (mm)",
                "C_HDC (mm²)",
                "the height-difference correlation ⟨(z(x + λ) − z(x))²⟩ against the lag λ, \
mean over the track's locations; the broad translucent lines have the fitted slope 2H \
over the lags 0.01–0.5 mm that H (legend) is fitted on",
            ),
        ] {
            let series: Vec<Points> = tracks
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    let h = inputs
                        .rows
                        .iter()
                        .find(|r| r.track == *t)
                        .map_or(
                            f64::NAN,
                            |r| if curve == "psd" { r.hurst } else { r.hurst_hdc },
                        );
                    Points {
                        label: format!("{t} (H {})", num(h, 2)),
                        color: k,
                        xy: track_curve(inputs, t, curve),
                        filled: false,
                    }
                })
                .filter(|s| !s.xy.is_empty())
                .collect();
            // A curve's colour is its track's index.
            let fits: Vec<Segment> = series
                .iter()
                .filter_map(|s| hurst_line(inputs, &tracks[s.color], curve, s))
                .collect();
            // The PSD falls to the right, the HDC rises: the legend goes where
            // the curves are not.
            let svg = figure::log_curves(&Axes { title, x, y }, &series, &fits, curve == "hdc")?;
            let csv: Vec<Vec<String>> = inputs
                .road
                .iter()
                .filter(|p| p.curve == curve)
                .map(|p| {
                    vec![
                        p.track.clone(),
                        p.location.clone(),
                        format!("{:e}", p.x),
                        format!("{:e}", p.y),
                    ]
                })
                .collect();
            html += &fig(
                &svg,
                &format!("{title}: {what}. One colour per track."),
                &csv_link(
                    &format!("road_{curve}.csv"),
                    &["track", "location", x, y],
                    &csv,
                ),
            );
            figures += 1;
        }
    }
    let rows: Vec<Vec<String>> = tracks
        .iter()
        .filter_map(|t| inputs.rows.iter().find(|r| r.track == *t))
        .map(|r| {
            vec![
                r.track.clone(),
                num(r.hurst, 3),
                num(r.hurst_hdc, 3),
                num(r.ra_micro_mm * 1e3, 1),
                num(r.ra_macro_mm, 3),
                num(r.rq_mm, 3),
                num(r.skewness, 2),
                num(r.kurtosis, 2),
                num(r.macro_wavelength_mm, 2),
            ]
        })
        .collect();
    html += "<h3>Roughness indices per track (table 3)</h3>\n";
    html += &table(
        &[
            "track",
            "Hurst H (PSD)",
            "Hurst H (HDC)",
            "Ra micro (µm)",
            "Ra macro (mm)",
            "Rq (mm)",
            "skewness",
            "kurtosis",
            "macro wavelength (mm)",
        ],
        &rows,
    );
    Ok(Section {
        title: "Road".into(),
        html,
        figures,
    })
}

/// The viscoelastic section (table 5): each compound's master curves with
/// the tire-runs' operating points at their shifted temperature T*.
pub(super) fn viscoelastic(inputs: &Inputs) -> Result<Section, ReportError> {
    let mut html = String::new();
    let mut figures = 0;
    if inputs.compounds.is_empty() {
        html += &missing("No compounds/*.toml in the folder: the master curves are not shown.");
    }
    let compound_rows = |id: String| inputs.rows.iter().filter(move |r| r.compound == id);
    for (key, title, y, log_y) in [
        (
            "e",
            "Storage modulus master curves",
            "storage modulus E′ (MPa)",
            true,
        ),
        (
            "tan",
            "Loss factor master curves",
            "loss factor tan δ (1)",
            false,
        ),
    ] {
        if inputs.compounds.is_empty() {
            break;
        }
        let pick = |r: &KpiRow| {
            if key == "e" {
                r.storage_modulus_mpa
            } else {
                r.loss_factor
            }
        };
        let curves: Vec<Points> = inputs
            .compounds
            .iter()
            .enumerate()
            .map(|(k, c)| {
                let m = &c.master_curve;
                let ys = if key == "e" {
                    &m.storage_modulus_mpa
                } else {
                    &m.loss_factor
                };
                Points {
                    label: c.id.clone(),
                    color: k,
                    xy: m
                        .temperature_c
                        .iter()
                        .copied()
                        .zip(ys.iter().copied())
                        .collect(),
                    filled: false,
                }
            })
            .collect();
        let marks: Vec<Points> = inputs
            .compounds
            .iter()
            .enumerate()
            .map(|(k, c)| Points {
                label: c.id.clone(),
                color: k,
                xy: compound_rows(c.id.clone())
                    .map(|r| (r.shifted_temperature_c, pick(r)))
                    .collect(),
                filled: false,
            })
            .collect();
        let svg = figure::curves_with_marks(
            &Axes {
                title,
                x: "temperature at the reference frequency (°C)",
                y,
            },
            &curves,
            &marks,
            log_y,
        )?;
        html += &fig(
            &svg,
            &format!(
                "{title}: each compound's master curve at its reference frequency (line), and \
each tire-run's operating point (circle): its shifted temperature T* — the mean surface \
temperature moved by WLF to the reference frequency from the road's solicitation \
frequency f = v_s / λ_macro — and the curve's value there."
            ),
            "",
        );
        figures += 1;
    }
    let rows: Vec<Vec<String>> = inputs
        .compounds
        .iter()
        .map(|c| {
            let t: Vec<f64> = compound_rows(c.id.clone())
                .map(|r| r.shifted_temperature_c)
                .filter(|t| t.is_finite())
                .collect();
            let lo = t.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            vec![
                c.id.clone(),
                num(c.reference_frequency_hz, 1),
                num(c.wlf.c1, 2),
                num(c.wlf.c2_k, 1),
                num(c.wlf.t_ref_c, 1),
                t.len().to_string(),
                num(lo, 1),
                num(hi, 1),
            ]
        })
        .collect();
    if !rows.is_empty() {
        html += &table(
            &[
                "compound",
                "reference frequency (Hz)",
                "WLF C1",
                "WLF C2 (K)",
                "T_ref (°C)",
                "tire-runs",
                "T* min (°C)",
                "T* max (°C)",
            ],
            &rows,
        );
    }
    Ok(Section {
        title: "Viscoelastic".into(),
        html,
        figures,
    })
}

/// The telemetry section (table 4): where on the tread's temperatures the friction
/// energy was dissipated, per axle.
pub(super) fn telemetry(inputs: &Inputs) -> Result<Section, ReportError> {
    use crate::kpi::energy_maps::{T_INNER_BINS, T_SURFACE_BINS};
    let mut html = String::new();
    let mut figures = 0;
    if inputs.maps.is_empty() {
        html += &missing(
            "No kpis.energy_maps.parquet beside the KPI table: extract again to add the maps.",
        );
    }
    let edges = |b: crate::kpi::energy_maps::Bins| -> Vec<f64> {
        (0..=b.n).map(|i| b.lower_edge(i)).collect()
    };
    let mut csv = Vec::new();
    for axle in Axle::ALL.into_iter().filter(|_| !inputs.maps.is_empty()) {
        let mut cells = vec![vec![0.0; T_INNER_BINS.n]; T_SURFACE_BINS.n];
        let mut tires = 0;
        for ((_, wheel), m) in &inputs.maps {
            if wheel.axle() != axle {
                continue;
            }
            tires += 1;
            for (i, col) in cells.iter_mut().enumerate() {
                for (j, c) in col.iter_mut().enumerate() {
                    *c += m.surface_inner[i * T_INNER_BINS.n + j] / 1e6;
                }
            }
        }
        let total: f64 = cells.iter().flatten().sum();
        let max = cells.iter().flatten().copied().fold(0.0f64, f64::max);
        for (i, col) in cells.iter().enumerate() {
            for (j, &e) in col.iter().enumerate().filter(|(_, e)| **e > 0.0) {
                csv.push(vec![
                    axle.to_string(),
                    num(T_SURFACE_BINS.lower_edge(i), 1),
                    num(T_INNER_BINS.lower_edge(j), 1),
                    num(e, 4),
                ]);
            }
        }
        let title = format!("Friction energy by tread temperature, {axle} axle");
        let svg = figure::heatmap(
            &Axes {
                title: &title,
                x: "surface temperature (°C)",
                y: "inner-liner temperature (°C)",
            },
            &edges(T_SURFACE_BINS),
            &edges(T_INNER_BINS),
            &cells,
        )?;
        html += &fig(
            &svg,
            &format!(
                "{title}: the friction energy of the season's {tires} {axle} tire-runs ({} MJ in all) by the surface and inner-liner temperature at which it was dissipated, 5 K bins (the first and last bins also hold what lies beyond them); white 0, darkest {} MJ, shade ∝ √energy.",
                num(total, 1),
                num(max, 2)
            ),
            "",
        );
        figures += 1;
    }
    if !csv.is_empty() {
        html += &csv_link(
            "energy_maps_by_axle.csv",
            &["axle", "t_surface_lo_c", "t_inner_lo_c", "energy_mj"],
            &csv,
        );
    }
    let (strips, n) = kpi_distributions(inputs)?;
    html += &strips;
    figures += n;
    Ok(Section {
        title: "Telemetry".into(),
        html,
        figures,
    })
}

/// Table-4 KPIs whose spread per track the telemetry section shows: column,
/// axis title, and the factor from the column's unit to the axis's.
const DISTRIBUTED_KPIS: [(&str, &str, f64); 4] = [
    ("t_surface_avg_c", "mean surface temperature (°C)", 1.0),
    ("friction_energy_j", "total friction energy (MJ)", 1e-6),
    ("sliding_distance_m", "sliding distance (km)", 1e-3),
    ("fz_avg_n", "mean vertical load (kN)", 1e-3),
];

/// Strip plots of [`DISTRIBUTED_KPIS`]: every tire-run's value at its
/// track's number (spread sideways by wheel), front and rear in two
/// colours; the track numbering in a table. Returns the HTML and how many
/// figures.
fn kpi_distributions(inputs: &Inputs) -> Result<(String, usize), ReportError> {
    let tracks = track_names(inputs);
    let mut html = String::new();
    for (column, label, scale) in DISTRIBUTED_KPIS {
        let groups: Vec<Points> = Axle::ALL
            .into_iter()
            .enumerate()
            .map(|(k, axle)| Points {
                label: format!("{axle} axle"),
                color: k,
                xy: inputs
                    .rows
                    .iter()
                    .filter(|r| r.axle == axle)
                    .filter_map(|r| {
                        let t = tracks.iter().position(|t| *t == r.track)?;
                        let v = r.number(column)? * scale;
                        // Left and right wheels side by side, front and rear apart.
                        let dx = 0.12 * (r.wheel.index() as f64 - 1.5);
                        Some((t as f64 + 1.0 + dx, v))
                    })
                    .collect(),
                filled: true,
            })
            .collect();
        let title = format!("Per track: {label}");
        let svg = figure::scatter(
            &Axes {
                title: &title,
                x: "track (number in the table below)",
                y: label,
            },
            &groups,
            &[],
            false,
        )?;
        html += &fig(
            &svg,
            &format!(
                "{title}: every tire-run's value (column {column}) at its track's number, the \
four wheels side by side (FL, FR, RL, RR), front and rear in two colours."
            ),
            "",
        );
    }
    let rows: Vec<Vec<String>> = tracks
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let n = inputs.rows.iter().filter(|r| r.track == *t).count();
            vec![(i + 1).to_string(), t.clone(), n.to_string()]
        })
        .collect();
    html += &table(&["#", "track", "tire-runs"], &rows);
    Ok((html, DISTRIBUTED_KPIS.len()))
}

fn track_names(inputs: &Inputs) -> Vec<String> {
    inputs
        .rows
        .iter()
        .map(|r| r.track.clone())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect()
}

/// Least squares y = a + b·x: (a, b, R²); None under 3 points or no spread in x.
pub(crate) fn line_fit(xy: &[(f64, f64)]) -> Option<(f64, f64, f64)> {
    let n = xy.len() as f64;
    if xy.len() < 3 {
        return None;
    }
    let mx = xy.iter().map(|p| p.0).sum::<f64>() / n;
    let my = xy.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = xy.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = xy.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let syy: f64 = xy.iter().map(|p| (p.1 - my).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let b = sxy / sxx;
    let a = my - b * mx;
    let r2 = if syy > 0.0 {
        sxy * sxy / (sxx * syy)
    } else {
        f64::NAN
    };
    Some((a, b, r2))
}

/// The physical-correlations section (paper 4.3): mean wear against total friction energy, per track and axle.
pub(super) fn physical(inputs: &Inputs) -> Result<Section, ReportError> {
    let names = track_names(inputs);
    let tracks: Vec<&str> = names.iter().map(String::as_str).collect();
    let mut html = String::from(
        "<p>Each mark is one tire and run: its mean wear (% of the new tread depth) \
against its total friction energy E = ∫ |F·v_s| dt (MJ), one colour per track, with \
each track's least-squares line; tires worn through (censored wear) are left out. The paper's physical correlation: on one track, wear \
grows about linearly with the energy; the tracks' slopes differ with the road and the \
temperatures.</p>\n",
    );
    let (mut figures, mut fits, mut csv) = (0, Vec::new(), Vec::new());
    for axle in Axle::ALL {
        let mut points = Vec::new();
        let mut lines = Vec::new();
        for (k, track) in tracks.iter().enumerate() {
            let xy: Vec<(f64, f64)> = inputs
                .rows
                .iter()
                .filter(|r| r.axle == axle && r.track == *track)
                .filter(|r| measured(r) && r.friction_energy_j.is_finite())
                .map(|r| (r.friction_energy_j / 1e6, r.wear_mean_pct))
                .collect();
            if xy.is_empty() {
                continue;
            }
            for r in inputs
                .rows
                .iter()
                .filter(|r| r.axle == axle && r.track == *track)
            {
                csv.push(vec![
                    r.track.clone(),
                    axle.to_string(),
                    r.run.clone(),
                    r.wheel.to_string(),
                    num(r.friction_energy_j / 1e6, 4),
                    num(r.wear_mean_pct, 4),
                    (!measured(r)).to_string(),
                ]);
            }
            if let Some((a, b, r2)) = line_fit(&xy) {
                let lo = xy.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
                let hi = xy.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
                lines.push(Segment {
                    color: Some(k),
                    from: (lo, a + b * lo),
                    to: (hi, a + b * hi),
                });
                fits.push(vec![
                    track.to_string(),
                    axle.to_string(),
                    xy.len().to_string(),
                    num(b, 3),
                    num(a, 2),
                    num(r2, 3),
                ]);
            }
            points.push(Points {
                label: track.to_string(),
                color: k,
                xy,
                filled: true,
            });
        }
        let title = format!("Wear against friction energy, {axle} axle");
        let svg = figure::scatter(
            &Axes {
                title: &title,
                x: "total friction energy E (MJ)",
                y: "mean wear (% of new tread)",
            },
            &points,
            &lines,
            true,
        )?;
        html += &fig(
            &svg,
            &format!(
                "{title}: one mark per tire-run, one colour and line (least squares) per track."
            ),
            "",
        );
        figures += 1;
    }
    let header = ["track", "axle", "n", "slope (%/MJ)", "intercept (%)", "R²"];
    html += &table(&header, &fits);
    html += &csv_link(
        "wear_vs_energy.csv",
        &[
            "track",
            "axle",
            "run",
            "wheel",
            "friction_energy_mj",
            "wear_mean_pct",
            "left_out",
        ],
        &csv,
    );
    let (svg_t, svg_s, table_ts) = slopes_and_skewness(inputs, &tracks)?;
    html += &fig(
        &svg_t,
        "Each track's wear-per-energy slope (the lines above, %/MJ) against the mean \
surface temperature of its tires (°C), front and rear axles: the paper's temperature \
dependence of the abrasion per joule (the rubber's viscoelastic temperature factor).",
        "",
    );
    html += &fig(
        &svg_s,
        "Each track's mean residual of one wear-per-energy line per axle (all tracks \
pooled, % of the new tread) against its road's skewness: the paper's road effect that \
energy alone leaves (plateau-like, negatively skewed roads abrade less).",
        &table(
            &[
                "track",
                "axle",
                "mean surface temperature (°C)",
                "slope (%/MJ)",
                "skewness",
                "mean residual of the pooled line (%)",
            ],
            &table_ts,
        ),
    );
    figures += 2;
    html += &reliability_table(inputs);
    Ok(Section {
        title: "Physical correlations".into(),
        html,
        figures,
    })
}

/// Two figures of the physical correlations: each track's slope against
/// its mean surface temperature, and each track's mean residual of one
/// line per axle (all tracks pooled) against its road's skewness; with
/// the table behind both.
fn slopes_and_skewness(
    inputs: &Inputs,
    tracks: &[&str],
) -> Result<(String, String, Vec<Vec<String>>), ReportError> {
    let mut slope_points = Vec::new();
    let mut skew_points = Vec::new();
    let mut rows = Vec::new();
    for (k, axle) in Axle::ALL.into_iter().enumerate() {
        let on_axle: Vec<&KpiRow> = inputs
            .rows
            .iter()
            .filter(|r| r.axle == axle && measured(r) && r.friction_energy_j.is_finite())
            .collect();
        let xy = |rs: &[&KpiRow]| -> Vec<(f64, f64)> {
            rs.iter()
                .map(|r| (r.friction_energy_j / 1e6, r.wear_mean_pct))
                .collect()
        };
        let pooled = line_fit(&xy(&on_axle));
        let (mut slopes, mut skews) = (Vec::new(), Vec::new());
        for track in tracks {
            let rs: Vec<&KpiRow> = on_axle
                .iter()
                .copied()
                .filter(|r| r.track == *track)
                .collect();
            if rs.is_empty() {
                continue;
            }
            let n = rs.len() as f64;
            let t_surface = rs.iter().map(|r| r.t_surface_avg_c).sum::<f64>() / n;
            let skewness = rs[0].skewness;
            let slope = line_fit(&xy(&rs)).map_or(f64::NAN, |f| f.1);
            let residual = pooled.map_or(f64::NAN, |(a, b, _)| {
                rs.iter()
                    .map(|r| r.wear_mean_pct - (a + b * r.friction_energy_j / 1e6))
                    .sum::<f64>()
                    / n
            });
            slopes.push((t_surface, slope));
            skews.push((skewness, residual));
            rows.push(vec![
                track.to_string(),
                axle.to_string(),
                num(t_surface, 1),
                num(slope, 3),
                num(skewness, 2),
                num(residual, 2),
            ]);
        }
        let group = |xy: Vec<(f64, f64)>| Points {
            label: format!("{axle} axle"),
            color: k,
            xy,
            filled: true,
        };
        slope_points.push(group(slopes));
        skew_points.push(group(skews));
    }
    let svg_t = figure::scatter(
        &Axes {
            title: "Wear-per-energy slope against surface temperature",
            x: "mean surface temperature of the track's tires (°C)",
            y: "slope of wear on energy (%/MJ)",
        },
        &slope_points,
        &[],
        false,
    )?;
    let svg_s = figure::scatter(
        &Axes {
            title: "What energy leaves: residual against road skewness",
            x: "road skewness Sk (1)",
            y: "track's mean residual (% of new tread)",
        },
        &skew_points,
        &[],
        false,
    )?;
    Ok((svg_t, svg_s, rows))
}

/// The figures a method adds about itself: PCA's explained variance per
/// component; the network's training curve and its validation error
/// against the second hidden layer's width (the search that chose it).
/// Returns the HTML and how many figures.
fn model_details(m: &crate::model::saved::SavedModel) -> Result<(String, usize), ReportError> {
    use crate::model::saved::ModelBody;
    match &m.model {
        ModelBody::Pca { pca, .. } => Ok((pca_explained_variance(pca)?, 1)),
        ModelBody::Ffnn { network, .. } => {
            Ok((training_curve(&network.net)? + &width_search(network)?, 2))
        }
        ModelBody::Physical { .. } => Ok((String::new(), 0)),
    }
}

/// PCA's share of the inputs' variance per component, kept ones in blue,
/// with its CSV.
fn pca_explained_variance(pca: &crate::model::pca::PcaFit) -> Result<String, ReportError> {
    let bars: Vec<Bar> = pca
        .proportions
        .iter()
        .enumerate()
        .map(|(i, p)| Bar {
            value: 100.0 * p,
            interval: None,
            color: if i < pca.kept { None } else { Some(7) },
        })
        .collect();
    let svg = figure::bars(
        &Axes {
            title: "PCA: variance explained per component",
            x: "principal component (1: the largest)",
            y: "share of the inputs' variance (%)",
        },
        &bars,
    )?;
    let kept: f64 = pca.proportions.iter().take(pca.kept).sum();
    let rows: Vec<Vec<String>> = pca
        .proportions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let cumulative: f64 = pca.proportions[..=i].iter().sum();
            vec![
                format!("PC{}", i + 1),
                // A hand-edited file may hold fewer: "–", not a panic.
                num(pca.eigenvalues.get(i).copied().unwrap_or(f64::NAN), 3),
                num(100.0 * p, 2),
                num(100.0 * cumulative, 2),
                (i < pca.kept).to_string(),
            ]
        })
        .collect();
    Ok(fig(
        &svg,
        &format!(
            "PCA of the {} standardised inputs: each component's share of their \
variance (eigenvalue of the correlation matrix over their sum, eq. 4); the {} kept \
components (blue) explain {} %, the regression uses their scores.",
            pca.inputs.len(),
            pca.kept,
            num(100.0 * kept, 1)
        ),
        &csv_link(
            "pca_explained_variance.csv",
            &[
                "component",
                "eigenvalue",
                "share_pct",
                "cumulative_pct",
                "kept",
            ],
            &rows,
        ),
    ))
}

/// The chosen network's training and validation error per epoch, the kept
/// epoch circled.
fn training_curve(net: &crate::model::ffnn::Ffnn) -> Result<String, ReportError> {
    let epochs = |k: usize| -> Vec<(f64, f64)> {
        net.curve
            .iter()
            .enumerate()
            .map(|(e, c)| ((e + 1) as f64, if k == 0 { c.0 } else { c.1 }))
            .collect()
    };
    let best: Vec<(f64, f64)> = net
        .curve
        .get(net.best_epoch.saturating_sub(1))
        .map(|c| vec![(net.best_epoch as f64, c.1)])
        .unwrap_or_default();
    let curve = figure::curves_with_marks(
        &Axes {
            title: "Network: training curve (Levenberg–Marquardt)",
            x: "epoch",
            y: "MSE (normalised units)",
        },
        &[
            Points {
                label: "training".into(),
                color: 0,
                xy: epochs(0),
                filled: false,
            },
            Points {
                label: "validation".into(),
                color: 1,
                xy: epochs(1),
                filled: false,
            },
        ],
        &[Points {
            label: String::new(),
            color: 1,
            xy: best,
            filled: false,
        }],
        true,
    )?;
    Ok(fig(
        &curve,
        &format!(
            "The chosen network's training: the mean squared error of the normalised \
wear on the training and the validation rows after each Levenberg–Marquardt epoch (log \
axis over six decades: a training error below runs along its floor); training stopped when the validation error had not improved for a while, and the \
weights of epoch {} (circled, the lowest validation error) were kept.",
            net.best_epoch
        ),
        "",
    ))
}

/// The network's validation error for each second-layer width tried.
fn width_search(network: &crate::model::network::NetworkFit) -> Result<String, ReportError> {
    let xy: Vec<(f64, f64)> = network
        .trials
        .iter()
        .map(|t| (t.hidden2 as f64, t.validation_mse))
        .collect();
    let svg = figure::curves_with_marks(
        &Axes {
            title: "Network: validation error against the second layer's width",
            x: "neurons in the second hidden layer",
            y: "validation MSE (normalised units)",
        },
        &[Points {
            label: "validation MSE".into(),
            color: 0,
            xy: xy.clone(),
            filled: false,
        }],
        &[Points {
            label: String::new(),
            color: 0,
            xy,
            filled: false,
        }],
        false,
    )?;
    Ok(fig(
        &svg,
        &format!(
            "The network's width search: the validation error (MSE of the normalised \
wear on the {} validation rows) of each second-layer width tried; the chosen network has {} \
and {} neurons.",
            network.validation_rows, network.net.hidden1, network.net.hidden2
        ),
        "",
    ))
}

/// The physical model's own preliminary analysis (`models/physical.json`,
/// training events): each track's line with the paper's reliability
/// indexes R1 and R2, and the correlations that chose its inputs.
fn reliability_table(inputs: &Inputs) -> String {
    use crate::model::saved::ModelBody;
    let Some(ModelBody::Physical { front, rear }) = inputs
        .models
        .iter()
        .map(|(_, m)| &m.model)
        .find(|m| matches!(m, ModelBody::Physical { .. }))
    else {
        return String::new();
    };
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    for a in [front, rear] {
        for l in &a.lines {
            rows.push(vec![
                l.track.clone(),
                a.axle.to_string(),
                l.n.to_string(),
                num(l.slope_pct_per_mj, 3),
                num(l.r1, 3),
                num(l.r2, 3),
                l.n_consistent.to_string(),
            ]);
        }
        notes.push(format!(
            "{} axle: slopes against mean surface temperature r = {} (weighted by R1, tracks \
with R2 ≥ 0.5), residuals of wear = a + b·E + c·E·T_surf against skewness r = {}",
            a.axle,
            num(a.slope_vs_t_surface, 2),
            num(a.residual_vs_skewness, 2)
        ));
    }
    format!(
        "<h3>Reliability of the per-track lines (the physical model's training events)</h3>\n\
<p>R1 = 1 − RMSE / (max − min wear) of a track's points about its line (1: every point on \
it); R2 = the track's consistent points (within 3 robust standard deviations of its line) \
over the most any track has; the paper weights by R1 and drops tracks of low R2 \
(section 4.3). {}.</p>\n{}",
        escape(&notes.join("; ")),
        table(
            &[
                "track",
                "axle",
                "n",
                "slope (%/MJ)",
                "R1",
                "R2",
                "consistent points"
            ],
            &rows
        )
    )
}

/// R² and RMSE of (measured, predicted) pairs, by the models' own
/// indicators (`model::metrics`); NaN where they are undefined (too few
/// pairs).
pub(crate) fn fit_quality(pairs: &[(f64, f64)]) -> (f64, f64) {
    let (measured, predicted): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
    crate::model::metrics::metrics(&measured, &predicted, 0)
        .map_or((f64::NAN, f64::NAN), |m| (m.r2, m.rmse))
}

/// The models section (tables 8, 9, 11): each fitted model's predictions against the
/// measurements, training and testing events apart.
pub(super) fn models(inputs: &Inputs) -> Result<Section, ReportError> {
    let mut html = String::new();
    let mut figures = 0;
    if inputs.models.is_empty() {
        html += &missing("No models/*.json in the folder: run `tirewear fit` to add this section.");
    }
    let mut summary = Vec::new();
    for (path, m) in &inputs.models {
        let p = predictions(inputs, m);
        let (r2_train, rmse_train) = fit_quality(&p.train);
        let (r2_test, rmse_test) = fit_quality(&p.test);
        let method = m.method();
        let title = format!("Predicted against measured wear: {method}");
        let svg = predictions_figure(&p, &title)?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        html += &fig(
            &svg,
            &format!(
                "{title} ({name}): filled marks training events, hollow testing events, grey the 1:1 \
line. Training R² {} RMSE {} %, testing R² {} RMSE {} %.{}{}",
                num(r2_train, 3),
                num(rmse_train, 2),
                num(r2_test, 3),
                num(rmse_test, 2),
                intervals_held(&p),
                whiskers_are(p.whisker_kinds)
            ),
            &predictions_csv(method, &p.csv),
        );
        figures += 1;
        let (extra, n) = model_details(m)?;
        html += &extra;
        figures += n;
        summary.push(vec![
            method.to_string(),
            p.train.len().to_string(),
            num(r2_train, 3),
            num(rmse_train, 2),
            p.test.len().to_string(),
            num(r2_test, 3),
            num(rmse_test, 2),
            coverage_share(p.inside[1]),
            coverage_share(p.inside_event[1]),
        ]);
    }
    if !summary.is_empty() {
        html += &table(
            &[
                "method",
                "training n",
                "training R²",
                "training RMSE (%)",
                "testing n",
                "testing R²",
                "testing RMSE (%)",
                "testing in 95 % PI",
                "testing in 95 % new-event PI",
            ],
            &summary,
        );
    }
    Ok(Section {
        title: "Wear models".into(),
        html,
        figures,
    })
}

/// One model's predictions of the measured tires, training and testing
/// events apart.
#[derive(Default)]
struct Predictions {
    /// (measured, predicted) mean wear (%) of the training events' tires.
    train: Vec<(f64, f64)>,
    /// The same for the testing events' tires.
    test: Vec<(f64, f64)>,
    /// The rows of `predictions_METHOD.csv` ([`predictions_csv`]).
    csv: Vec<Vec<String>>,
    /// Per split, of the tires with a 95 % prediction interval, how many
    /// hold their measured wear (docs/models.md).
    inside: [Coverage; 2],
    /// The same for the new-event interval.
    inside_event: [Coverage; 2],
    /// Each testing tire's interval as a whisker: a testing event is a new
    /// event to the model, so its new-event interval where the fit kept
    /// the event errors, else the model's own.
    whiskers: Vec<Whisker>,
    /// How many whiskers are the model's own interval (0) and how many the
    /// new-event one (1).
    whisker_kinds: [usize; 2],
}

/// `m`'s predictions of the measured tires of its training and testing
/// events (a tire it cannot predict is left out).
fn predictions(inputs: &Inputs, m: &SavedModel) -> Predictions {
    let mut out = Predictions::default();
    for r in inputs.rows.iter().filter(|r| measured(r)) {
        let Ok((p, interval)) = m.predict_row_within(r, Some(IntervalLevel::P95)) else {
            continue;
        };
        if !p.is_finite() {
            continue;
        }
        let split = if m.training_events.contains(&r.event) {
            out.train.push((r.wear_mean_pct, p));
            0
        } else if m.testing_events.contains(&r.event) {
            out.test.push((r.wear_mean_pct, p));
            1
        } else {
            continue;
        };
        if let Some((low, high)) = interval {
            out.inside[split].add(r.wear_mean_pct, low, high);
        }
        let event = m.event_interval_around(p, r.axle, IntervalLevel::P95);
        if let Some((low, high)) = event {
            out.inside_event[split].add(r.wear_mean_pct, low, high);
        }
        let drawn = if event.is_some() { event } else { interval };
        if let (1, Some(y)) = (split, drawn) {
            out.whiskers.push(Whisker {
                color: 1,
                x: r.wear_mean_pct,
                y,
            });
            out.whisker_kinds[usize::from(event.is_some())] += 1;
        }
        let (low, high) = interval.unwrap_or((f64::NAN, f64::NAN));
        let (event_low, event_high) = event.unwrap_or((f64::NAN, f64::NAN));
        out.csv.push(vec![
            r.run.clone(),
            r.wheel.to_string(),
            ["training", "testing"][split].into(),
            num(r.wear_mean_pct, 4),
            num(p, 4),
            num(low, 4),
            num(high, 4),
            num(event_low, 4),
            num(event_high, 4),
        ]);
    }
    out
}

/// A coverage as a percentage, "–" where no tire had an interval.
fn coverage_share(c: Coverage) -> String {
    c.share()
        .map_or("–".into(), |s| format!("{} %", num(100.0 * s, 1)))
}

/// The caption's sentences on how many measured tires the 95 % intervals
/// hold (empty where the model gives none).
fn intervals_held(p: &Predictions) -> String {
    let mut held = if p.inside.iter().any(|c| c.of > 0) {
        format!(
            " The 95 % prediction intervals hold {} of the training and {} of the testing \
tires' measured wear.",
            coverage_share(p.inside[0]),
            coverage_share(p.inside[1])
        )
    } else {
        String::new()
    };
    if p.inside_event.iter().any(|c| c.of > 0) {
        held += &format!(
            " The 95 % intervals for a new event (from the training tires' errors with \
their event left out) hold {} and {}.",
            coverage_share(p.inside_event[0]),
            coverage_share(p.inside_event[1])
        );
    }
    held
}

/// The caption's sentence on what the whiskers are.
fn whiskers_are(kinds: [usize; 2]) -> &'static str {
    match kinds {
        [0, 0] => "",
        [_, 0] => " Whiskers: each testing tire's 95 % prediction interval.",
        [0, _] => " Whiskers: each testing tire's 95 % interval for a new event.",
        _ => {
            " Whiskers: each testing tire's 95 % interval for a new event, the model's own \
95 % prediction interval where the fit kept no event errors for its axle."
        }
    }
}

/// Predicted against measured wear, training events filled and testing
/// events hollow with their intervals as whiskers, and the 1:1 line.
fn predictions_figure(p: &Predictions, title: &str) -> Result<String, ReportError> {
    let all = p.train.iter().chain(&p.test);
    let lo = all
        .clone()
        .map(|p| p.0.min(p.1))
        .fold(f64::INFINITY, f64::min);
    let hi = all.map(|p| p.0.max(p.1)).fold(f64::NEG_INFINITY, f64::max);
    figure::scatter_with_whiskers(
        &Axes {
            title,
            x: "measured mean wear (%)",
            y: "predicted mean wear (%)",
        },
        &[
            Points {
                label: "training".into(),
                color: 0,
                xy: p.train.clone(),
                filled: true,
            },
            Points {
                label: "testing".into(),
                color: 1,
                xy: p.test.clone(),
                filled: false,
            },
        ],
        &[Segment {
            color: None,
            from: (lo, lo),
            to: (hi, hi),
        }],
        (&p.whiskers, figure::WHISKER_REACH),
        false,
    )
}

/// The link to `predictions_METHOD.csv`: each tire's measured and predicted
/// wear with its intervals.
fn predictions_csv(method: &str, rows: &[Vec<String>]) -> String {
    csv_link(
        &format!("predictions_{method}.csv"),
        &[
            "run",
            "wheel",
            "split",
            "measured_pct",
            "predicted_pct",
            "interval_95_low_pct",
            "interval_95_high_pct",
            "new_event_95_low_pct",
            "new_event_95_high_pct",
        ],
        rows,
    )
}

/// A threshold in at most four decimals, trailing zeros dropped.
fn short(v: f64) -> String {
    let s = num(v, 4);
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A candidate's threshold from gap.json: a pair or band candidate's is the
/// index of its two edges, printed as the edges.
fn threshold_text(c: &Value) -> String {
    let theta = f(&c["threshold"]);
    if let Some(condition) = c["feature"]["BandEnergy"]["condition"].as_u64()
        && (condition as usize) < crate::kpi::cpu::condition_map::N_CONDITIONS
    {
        return crate::gap::candidates::Feature::BandEnergy {
            condition: condition as usize,
            component: crate::kpi::cpu::condition_map::Component::Total,
        }
        .format_threshold(theta);
    }
    let pair = &c["feature"]["PairEnergy"];
    match (
        pair["pair"].as_u64(),
        pair["first_above"].as_bool(),
        pair["second_above"].as_bool(),
    ) {
        (Some(p), Some(first_above), Some(second_above))
            if (p as usize) < crate::kpi::cpu::condition_map::N_PAIRS =>
        {
            crate::gap::candidates::Feature::PairEnergy {
                pair: p as usize,
                first_above,
                second_above,
            }
            .format_threshold(theta)
        }
        _ => short(theta),
    }
}

/// Flagged slices drawn in the gap's bar chart, and traced in its shrink chart.
const SHOWN_SLICES: usize = 12;
const SHRINK_SLICES: usize = 5;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The gap section: where (slices with intervals), which effect
/// (candidate ranking) and how far it shrinks (RMSE after each step).
pub(super) fn gap(inputs: &Inputs) -> Result<Section, ReportError> {
    let Some(g) = &inputs.gap else {
        return Ok(Section {
            title: "Sim-to-real gap".into(),
            html: missing("No gap/gap.json in the folder: run `tirewear gap` to add this section."),
            figures: 0,
        });
    };
    let mut html = format!(
        "<p>Baseline: {}. Training events {} (RMSE {} %), testing events {} (RMSE {} %).</p>\n",
        escape(g["baseline"].as_str().unwrap_or("?")),
        g["training_events"].as_array().map_or(0, |a| a.len()),
        num(f(&g["training"]["rmse_pct"]), 2),
        g["testing_events"].as_array().map_or(0, |a| a.len()),
        num(f(&g["testing"]["rmse_pct"]), 2),
    );
    html += &gap_findings(g);
    let mut figures = 0;
    // Where: the flagged slices' mean residual with its 95 % interval.
    let slices: Vec<&Value> = g["slices"].as_array().into_iter().flatten().collect();
    if slices.is_empty() {
        html += "<p>No slice of the season differs from the rest beyond chance: the \
model's residuals show no place where it and the measurements disagree.</p>\n";
    } else {
        html += &flagged_slices(&slices)?;
        figures += 1;
    }
    // Which: the candidates, best first.
    html += &candidates_table(g);
    // How far: RMSE after each step.
    let steps: Vec<&Value> = g["steps"].as_array().into_iter().flatten().collect();
    if !steps.is_empty() {
        html += &shrink_chart(&steps, &slices)?;
        figures += 1;
    }
    // Each added term's wear against the residual it is there to explain.
    let terms: Vec<&str> = steps
        .iter()
        .skip(1)
        .filter_map(|s| s["added"].as_str())
        .collect();
    let measured_wear: std::collections::HashMap<(String, String), f64> = inputs
        .rows
        .iter()
        .map(|r| ((r.run.clone(), r.wheel.to_string()), r.wear_mean_pct))
        .collect();
    let tires: Vec<&Value> = g["terms_wear"].as_array().into_iter().flatten().collect();
    for (j, term) in terms.iter().enumerate() {
        if let Some(figure) = term_figure(j, term, &tires, &measured_wear)? {
            html += &figure;
            figures += 1;
        }
    }
    if g["final_terms"].as_array().is_some_and(|t| t.is_empty()) {
        html += "<p>No term was added: nothing the candidates describe explains the gap \
beyond chance.</p>\n";
    }
    Ok(Section {
        title: "Sim-to-real gap".into(),
        html,
        figures,
    })
}

/// What the diagnosis found, in words (gap.json from before 2026-11-26 has
/// none: empty).
fn gap_findings(g: &Value) -> String {
    let findings: Vec<&str> = g["findings"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .collect();
    if findings.is_empty() {
        return String::new();
    }
    let mut html = "<h3>Findings</h3>\n".to_string();
    for line in findings {
        html += &format!("<p>{}</p>\n", escape(line));
    }
    html
}

/// The flagged slices' difference of mean residuals with its 95 %
/// interval (the first [`SHOWN_SLICES`] drawn), their table and CSV.
fn flagged_slices(slices: &[&Value]) -> Result<String, ReportError> {
    // A strong effect flags hundreds of overlapping slices: the first
    // ones in the diagnosis's order are drawn, all are in the CSV.
    let shown = &slices[..slices.len().min(SHOWN_SLICES)];
    let bars: Vec<Bar> = shown
        .iter()
        .map(|s| {
            // Value indexing gives Null (NaN here) for a short or
            // missing interval, where Vec indexing would panic.
            let ci = s["ci_pct"].as_array().map(|_| &s["ci_pct"]);
            Bar {
                value: f(&s["difference_pct"]),
                interval: ci
                    .map(|c| (f(&c[0]), f(&c[1])))
                    .filter(|(lo, hi)| lo.is_finite() && hi.is_finite()),
                color: None,
            }
        })
        .collect();
    let svg = figure::bars(
        &Axes {
            title: "Where the model and the track disagree",
            x: "flagged slice (table)",
            y: "gap against the rest, measured − predicted (%)",
        },
        &bars,
    )?;
    let rows: Vec<Vec<String>> = slices
        .iter()
        .enumerate()
        .map(|(i, s)| {
            vec![
                (i + 1).to_string(),
                s["name"].as_str().unwrap_or("").to_string(),
                s["n"].to_string(),
                num(f(&s["mean_residual_pct"]), 2),
                num(f(&s["difference_pct"]), 2),
                num(f(&s["p_adjusted"]), 4),
            ]
        })
        .collect();
    let header = [
        "#",
        "slice",
        "n",
        "mean residual (%)",
        "difference (%)",
        "p adj.",
    ];
    Ok(fig(
        &svg,
        &format!(
            "Flagged slices: how much more (or less) the tires of each slice wear than \
the model predicts, against the rest of the season (difference of mean residuals, % of \
the new tread), with its 95 % interval; the slices are numbered as in the table. {} \
slices flagged{}.",
            slices.len(),
            if slices.len() > shown.len() {
                format!(
                    "; the first {} in the diagnosis's order are drawn, all are in the CSV",
                    shown.len()
                )
            } else {
                String::new()
            }
        ),
        &format!(
            "{}{}",
            table(&header, &rows[..shown.len()]),
            csv_link("flagged_slices.csv", &header, &rows)
        ),
    ))
}

/// The ten best candidate effects by held-out gain, as a table.
fn candidates_table(g: &Value) -> String {
    let candidates: Vec<Vec<String>> = g["candidates"]
        .as_array()
        .into_iter()
        .flatten()
        .take(10)
        .map(|c| {
            vec![
                c["name"].as_str().unwrap_or("").to_string(),
                threshold_text(c),
                num(f(&c["cv_gain"]), 3),
                num(f(&c["p_adjusted"]), 4),
            ]
        })
        .collect();
    "<h3>Candidate effects (ten best by held-out gain)</h3>\n".to_string()
        + &table(
            &["candidate", "threshold", "CV gain", "p adj."],
            &candidates,
        )
}

/// The RMSE after each added term on the training and testing events and
/// inside the first flagged slices: chart and table.
fn shrink_chart(steps: &[&Value], slices: &[&Value]) -> Result<String, ReportError> {
    let series = |key: &str| -> Vec<f64> { steps.iter().map(|s| f(&s[key]["rmse_pct"])).collect() };
    // Inside each flagged slice too (numbered as in the slices' table).
    let in_slice = |k: usize| -> Vec<f64> {
        steps
            .iter()
            .map(|s| f(&s["slices"][k]["rmse_pct"]))
            .collect()
    };
    let mut lines = vec![
        ("training".to_string(), 0, series("training")),
        ("testing".to_string(), 1, series("testing")),
    ];
    let traced = slices.len().min(SHRINK_SLICES);
    lines.extend((0..traced).map(|k| (format!("slice {}", k + 1), k + 2, in_slice(k))));
    let svg = figure::steps(
        &Axes {
            title: "How far the gap shrinks",
            x: "step (0: baseline; then each added term)",
            y: "RMSE (% of new tread)",
        },
        &lines,
    )?;
    let header: Vec<String> = ["step", "added", "training RMSE (%)", "testing RMSE (%)"]
        .into_iter()
        .map(String::from)
        .chain((0..traced).map(|k| format!("slice {} RMSE (%)", k + 1)))
        .collect();
    let rows: Vec<Vec<String>> = steps
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let mut row = vec![
                i.to_string(),
                s["added"].as_str().unwrap_or("").to_string(),
                num(f(&s["training"]["rmse_pct"]), 3),
                num(f(&s["testing"]["rmse_pct"]), 3),
            ];
            row.extend((0..traced).map(|k| num(f(&s["slices"][k]["rmse_pct"]), 3)));
            row
        })
        .collect();
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    Ok(fig(
        &svg,
        "Shrink table: the RMSE of the baseline, then after each term the selection \
added, on the training and the testing events and inside the first flagged slices \
(numbered as in the slices' table).",
        &table(&header, &rows),
    ))
}

/// Term `j`'s (`term`) wear in the final model against the residual it is
/// there to explain, per tire-run with a measured wear (`measured_wear` by
/// run and wheel); None when no tire has both.
fn term_figure(
    j: usize,
    term: &str,
    tires: &[&Value],
    measured_wear: &std::collections::HashMap<(String, String), f64>,
) -> Result<Option<String>, ReportError> {
    let mut groups: Vec<Points> = Axle::ALL
        .into_iter()
        .enumerate()
        .map(|(k, a)| Points {
            label: format!("{a} axle"),
            color: k,
            xy: Vec::new(),
            filled: true,
        })
        .collect();
    for t in tires {
        let key = (
            t["run"].as_str().unwrap_or("").to_string(),
            t["wheel"].as_str().unwrap_or("").to_string(),
        );
        let Some(&wear) = measured_wear.get(&key) else {
            continue;
        };
        let part = f(&t["by_term_pct"][j]);
        // What is left to explain without this term.
        let residual = wear - f(&t["predicted_pct"]) + part;
        if !(part.is_finite() && residual.is_finite()) {
            continue;
        }
        let axle = usize::from(t["axle"].as_str() == Some("rear"));
        groups[axle].xy.push((part, residual));
    }
    let all: Vec<(f64, f64)> = groups.iter().flat_map(|g| g.xy.iter().copied()).collect();
    if all.is_empty() {
        return Ok(None);
    }
    let r = line_fit(&all).map_or(f64::NAN, |f| f.2.sqrt());
    let lo = all
        .iter()
        .map(|p| p.0.min(p.1))
        .fold(f64::INFINITY, f64::min);
    let hi = all
        .iter()
        .map(|p| p.0.max(p.1))
        .fold(f64::NEG_INFINITY, f64::max);
    let title = format!("Term {}: its wear against the residual it explains", j + 1);
    let svg = figure::scatter(
        &Axes {
            title: &title,
            x: "the term's wear (% of new tread)",
            y: "residual without the term (%)",
        },
        &groups,
        &[Segment {
            color: None,
            from: (lo, lo),
            to: (hi, hi),
        }],
        false,
    )?;
    Ok(Some(fig(
        &svg,
        &format!(
            "Term {} ({term}): each tire-run's wear from this term in the final model \
against what the measurement leaves without it (measured − final prediction + the \
term's wear), grey the 1:1 line; |correlation| {}. A term that explains a real effect \
follows the residual along the line.",
            j + 1,
            num(r, 2)
        ),
        "",
    )))
}

/// The performance section, when `tirewear bench` JSONs are given: with
/// two or more, first each line's time on every machine and its speed
/// against the first file's; then, for each file, every line's speed
/// against its reference (the memory pass for the kernels, zstd alone for
/// decoding, the 10 s target for the gap).
pub(super) fn performance(inputs: &Inputs) -> Result<Option<Section>, ReportError> {
    let (mut html, mut figures) = (String::new(), 0);
    if inputs.bench.len() > 1 {
        html += &comparison(&inputs.bench)?;
        figures += 1;
    }
    for b in &inputs.bench {
        if inputs.bench.len() > 1 {
            html += &format!("<h3>{}</h3>\n", escape(&b.label));
        }
        html += &one_machine(&b.json)?;
        figures += 1;
    }
    Ok((figures > 0).then(|| Section {
        title: "Performance".into(),
        html,
        figures,
    }))
}

/// One bench file's lines, each against its own reference.
fn one_machine(b: &Value) -> Result<String, ReportError> {
    let lines: Vec<&Value> = b["lines"].as_array().into_iter().flatten().collect();
    let kernels: Vec<&str> = lines
        .iter()
        .filter_map(|l| l["kernel"].as_str())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let color_of = |l: &Value| {
        let k = l["kernel"].as_str().unwrap_or("");
        kernels.iter().position(|x| *x == k).unwrap_or(0)
    };
    let bars: Vec<Bar> = lines
        .iter()
        .map(|l| Bar {
            value: f(&l["vs_memory_pass"]),
            interval: None,
            color: Some(color_of(l)),
        })
        .collect();
    let rows: Vec<Vec<String>> = lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            vec![
                (i + 1).to_string(),
                l["kernel"].as_str().unwrap_or("").to_string(),
                l["size"].as_str().unwrap_or("").to_string(),
                l["engine"].as_str().unwrap_or("").to_string(),
                num(f(&l["seconds"]) * 1e3, 2),
                l["reference"].as_str().unwrap_or("memory pass").to_string(),
                num(f(&l["vs_memory_pass"]), 3),
            ]
        })
        .collect();
    let svg = figure::bars(
        &Axes {
            title: "Speed against each line's reference",
            x: "benchmark line (table)",
            y: "reference time / time (1)",
        },
        &bars,
    )?;
    Ok(format!(
        "<p>{}</p>\n{}",
        machine(b),
        fig(
            &svg,
            "Each benchmark line's speed as the reference's time over its time: above 1 \
faster than the reference (a plain memory pass over the same buffer for the kernels, zstd \
alone over the same chunks for decoding, the 10 s target for the gap diagnosis, the step \
solved in the other space for Levenberg–Marquardt's step, none (0) for the network's fit); \
one colour per kernel, the lines numbered as in the table.",
            &table(
                &[
                    "#",
                    "kernel",
                    "size",
                    "engine",
                    "time (ms)",
                    "reference",
                    "vs reference"
                ],
                &rows,
            ),
        )
    ))
}

/// "CPU: …; GPU: …." of a bench file.
fn machine(b: &Value) -> String {
    format!(
        "CPU: {}; GPU: {}.",
        escape(b["cpu"].as_str().unwrap_or("?")),
        escape(b["gpu"].as_str().unwrap_or("none"))
    )
}

/// What a line measures, the same on every machine: its kernel, size and
/// engine, the engine's "N threads" (or "N thr") written "all threads"
/// where N is the file's own thread count, so that a 2-core and a 16-core
/// machine compare their all-thread lines.
fn line_key(line: &Value, threads: u64) -> [String; 3] {
    let text = |k: &str| line[k].as_str().unwrap_or("").to_string();
    let mut engine = text("engine");
    if threads > 1 {
        for unit in ["threads", "thr"] {
            let own = format!(", {threads} {unit}");
            if engine.ends_with(&own) {
                engine.truncate(engine.len() - own.len());
                engine += ", all threads";
                break;
            }
        }
    }
    [text("kernel"), text("size"), engine]
}

/// The lines of several bench files side by side: each line (by
/// [`line_key`], in the order the files first list them) with its time on
/// every machine, and its speed on each machine against the first file's
/// (the first file's time over this file's, the same work both times).
fn comparison(files: &[super::BenchFile]) -> Result<String, ReportError> {
    let mut keys: Vec<[String; 3]> = Vec::new();
    let mut seconds: Vec<Vec<Option<f64>>> = Vec::new();
    for (i, b) in files.iter().enumerate() {
        let threads = b.json["threads"].as_u64().unwrap_or(0);
        for l in b.json["lines"].as_array().into_iter().flatten() {
            let key = line_key(l, threads);
            let row = match keys.iter().position(|k| *k == key) {
                Some(row) => row,
                None => {
                    keys.push(key);
                    seconds.push(vec![None; files.len()]);
                    keys.len() - 1
                }
            };
            let t = f(&l["seconds"]);
            // A line listed twice in one file: its first time counts.
            if seconds[row][i].is_none() && t.is_finite() && t > 0.0 {
                seconds[row][i] = Some(t);
            }
        }
    }
    let base = &files[0].label;
    // Each line's speed on each machine: the first file's time over its own.
    let speeds: Vec<Vec<Option<f64>>> = seconds
        .iter()
        .map(|times| times.iter().map(|t| Some(times[0]? / (*t)?)).collect())
        .collect();
    // The figure: the lines the first file and at least one other have.
    let compared: Vec<usize> = (0..keys.len())
        .filter(|&r| speeds[r].iter().skip(1).any(Option::is_some))
        .collect();
    let series: Vec<(String, usize)> = files
        .iter()
        .enumerate()
        .map(|(i, b)| (b.label.clone(), i))
        .collect();
    let groups: Vec<Vec<Option<f64>>> = compared.iter().map(|&r| speeds[r].clone()).collect();
    let title = format!("Speed against {base}");
    let y = format!("{base}'s time / time (1)");
    let svg = figure::grouped_bars(
        &Axes {
            title: &title,
            x: "benchmark line (table)",
            y: &y,
        },
        &series,
        &groups,
        1.0,
    )?;
    let mut header: Vec<String> = ["#", "kernel", "size", "engine"].map(String::from).to_vec();
    for b in files {
        header.push(format!("{} (ms)", b.label));
    }
    for b in &files[1..] {
        header.push(format!("{} vs {base}", b.label));
    }
    let dash = || "–".to_string();
    let mut rows: Vec<Vec<String>> = Vec::new();
    // Lines the comparison leaves out, by the files that hold them.
    let mut only: Vec<(String, Vec<String>)> = Vec::new();
    for (r, key) in keys.iter().enumerate() {
        let Some(n) = compared.iter().position(|&c| c == r) else {
            let holders: Vec<&str> = (0..files.len())
                .filter(|&i| seconds[r][i].is_some())
                .map(|i| files[i].label.as_str())
                .collect();
            let holders = holders.join(", ");
            let line = format!("{} ({}, {})", key[0], key[1], key[2]);
            match only.iter_mut().find(|(h, _)| *h == holders) {
                Some((_, lines)) => lines.push(line),
                None => only.push((holders, vec![line])),
            }
            continue;
        };
        let mut row = vec![
            (n + 1).to_string(),
            key[0].clone(),
            key[1].clone(),
            key[2].clone(),
        ];
        row.extend(
            seconds[r]
                .iter()
                .map(|t| t.map_or_else(dash, |t| num(t * 1e3, 2))),
        );
        row.extend(
            speeds[r][1..]
                .iter()
                .map(|s| s.map_or_else(dash, |s| num(s, 3))),
        );
        rows.push(row);
    }
    let machines: String = files
        .iter()
        .map(|b| format!("<li>{}: {}</li>", escape(&b.label), machine(&b.json)))
        .collect();
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut html = format!(
        "<p>{} bench files, one machine each:</p>\n<ul>{machines}</ul>\n{}",
        files.len(),
        fig(
            &svg,
            &format!(
                "Each line measured on several machines (the same kernel, input size and \
engine; a machine's all-thread lines compared with another's, whatever their thread counts): \
its speed on each machine as {base}'s time over that machine's time, above 1 faster; one \
colour per file, the dashed line at 1, the lines numbered as in the table."
            ),
            &table(&header, &rows),
        )
    );
    for (holders, lines) in &only {
        html += &format!(
            "<p>Only in {} (not compared): {}.</p>\n",
            escape(holders),
            escape(&lines.join("; "))
        );
    }
    Ok(html)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_fit_and_fit_quality_by_hand() {
        // y = 1 + 2x exactly: a 1, b 2, R² 1.
        let (a, b, r2) = line_fit(&[(0.0, 1.0), (1.0, 3.0), (2.0, 5.0)]).unwrap();
        assert!((a - 1.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12 && (r2 - 1.0).abs() < 1e-12);
        // (0,0) (1,2) (2,1): mean x 1, y 1; sxx 2, sxy 1, syy 2: b 0.5, a 0.5, R² 0.25.
        let (a, b, r2) = line_fit(&[(0.0, 0.0), (1.0, 2.0), (2.0, 1.0)]).unwrap();
        assert!((a - 0.5).abs() < 1e-12 && (b - 0.5).abs() < 1e-12 && (r2 - 0.25).abs() < 1e-12);
        assert!(line_fit(&[(1.0, 1.0), (1.0, 2.0), (1.0, 3.0)]).is_none());
        // measured (1, 2, 3), predicted (1, 2, 5): SSE 4, SST 2: R² −1, RMSE √(4/3).
        let (r2, rmse) = fit_quality(&[(1.0, 1.0), (2.0, 2.0), (3.0, 5.0)]);
        assert!((r2 + 1.0).abs() < 1e-12 && (rmse - (4.0f64 / 3.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_machines_own_thread_count_reads_all_threads() {
        let line = |engine: &str| serde_json::json!({"kernel": "k", "size": "s", "engine": engine});
        let engine = |e: &str, threads: u64| line_key(&line(e), threads)[2].clone();
        assert_eq!(engine("cpu, 16 threads", 16), "cpu, all threads");
        assert_eq!(engine("cpu realfft, 2 thr", 2), "cpu realfft, all threads");
        // Another count, or a count inside a word, is left as written.
        assert_eq!(engine("cpu, 8 threads", 16), "cpu, 8 threads");
        assert_eq!(engine("cpu, 1 thread", 1), "cpu, 1 thread");
        assert_eq!(
            engine("gpu, 16 threads upload", 16),
            "gpu, 16 threads upload"
        );
        assert_eq!(
            line_key(&line("gpu"), 4),
            ["k", "s", "gpu"].map(String::from)
        );
    }

    #[test]
    fn band_and_pair_thresholds_print_as_their_edges() {
        // A band of slip ratio (condition 0), index 0: bins 3 to 6 of 0.02
        // from −0.3; a pair's index 23: edges (4, 3) of combined slip and
        // surface temperature (as in gap::candidates' tests).
        let band = serde_json::json!({
            "threshold": 0.0,
            "feature": {"BandEnergy": {"condition": 0, "component": "Lateral"}}
        });
        assert_eq!(threshold_text(&band), "-0.2400 and -0.1800");
        let pair = (0..crate::kpi::cpu::condition_map::N_PAIRS)
            .find(|&p| crate::kpi::cpu::condition_map::pair_name(p) == "combined_slip:t_surface_c")
            .unwrap();
        let pair = serde_json::json!({
            "threshold": 23.0,
            "feature": {"PairEnergy": {"pair": pair, "first_above": true, "second_above": false}}
        });
        assert_eq!(threshold_text(&pair), "(0.06000, 60.00 °C)");
        let plain = serde_json::json!({"threshold": 84.5, "feature": "HotSurfaceEnergy"});
        assert_eq!(threshold_text(&plain), "84.5");
    }
}
