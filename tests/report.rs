//! `tirewear report`: the demo season's page, its structure and its numbers.

mod common;

use tirewear::model::fit::{FitSettings, Method, fit_method, split};
use tirewear::model::saved::save_all;

/// The values of attribute `name` in `html`.
fn attributes<'a>(html: &'a str, name: &str) -> Vec<&'a str> {
    let key = format!("{name}=\"");
    html.match_indices(&key)
        .map(|(i, _)| {
            let rest = &html[i + key.len()..];
            &rest[..rest.find('"').expect("closed attribute")]
        })
        .collect()
}

/// The least-squares line of `y` on `x` through `pairs`, by the closed form
/// slope = Σ(x−x̄)(y−ȳ) / Σ(x−x̄)², and the largest |residual| from it.
fn least_squares(pairs: &[(f64, f64)]) -> (f64, f64) {
    let n = pairs.len() as f64;
    let (mx, my) = (
        pairs.iter().map(|q| q.0).sum::<f64>() / n,
        pairs.iter().map(|q| q.1).sum::<f64>() / n,
    );
    let slope = pairs.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum::<f64>()
        / pairs.iter().map(|q| (q.0 - mx).powi(2)).sum::<f64>();
    let worst = pairs
        .iter()
        .map(|q| (q.1 - my - slope * (q.0 - mx)).abs())
        .fold(0.0, f64::max);
    (slope, worst)
}

/// Percent-decodes a `data:` URL's payload.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            out.push(u8::from_str_radix(&s[i + 1..i + 3], 16).unwrap());
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).unwrap()
}

#[test]
fn the_demo_report_has_every_section_its_figures_and_no_external_url() {
    let dir = tempfile::tempdir().unwrap();
    let rows = common::demo_kpis(dir.path());
    // Fit the PCA model (quick) and diagnose the gap, as `tirewear demo` does.
    let settings = FitSettings::default();
    let s = split(&rows, None).unwrap();
    let (pca, _) = fit_method(Method::Pca, &s, &settings).unwrap();
    let (physical, _) = fit_method(Method::Physical, &s, &settings).unwrap();
    save_all(&[pca.clone(), physical.clone()], &dir.path().join("models")).unwrap();
    let gap_settings = tirewear::gap::report::GapSettings {
        wlf: tirewear::ingest::compound::read_wlf(&dir.path().join("compounds")).unwrap(),
        ..Default::default()
    };
    use tirewear::gap::report::{Baseline, diagnose_file, write_diagnosis};
    let d = diagnose_file(
        &dir.path().join("kpis.parquet"),
        &Baseline::Physics,
        &gap_settings,
    )
    .unwrap();
    write_diagnosis(&d, &dir.path().join("gap")).unwrap();

    let out = dir.path().join("report.html");
    let summary = tirewear::report::write_report(dir.path(), &out, &[]).unwrap();
    assert!(summary.left_out.is_empty(), "{:?}", summary.left_out);
    let html = std::fs::read_to_string(&out).unwrap();

    // Every section, in order.
    let want = [
        "Season",
        "Road",
        "Viscoelastic",
        "Telemetry",
        "Physical correlations",
        "Wear models",
        "Sim-to-real gap",
    ];
    assert_eq!(summary.sections, want);
    for (i, title) in want.iter().enumerate() {
        assert!(
            html.contains(&format!("<h2>{}. {title}</h2>", i + 1)),
            "{title}"
        );
    }
    // Figures: the season's wear by event, the road's PSD and HDC, the master curves' E′ and tan δ, an
    // energy map per axle, four table-4 KPIs per track, two axles of wear against energy, the slopes
    // against temperature and the residuals against skewness, one model and
    // its explained variance, the physical model's predictions, and the
    // gap's shrink chart (plus the slices'
    // bars when a slice is flagged).
    let svgs: Vec<&str> = html.split("<svg").skip(1).collect();
    assert_eq!(svgs.len(), summary.figures);
    let flagged = !d.slices.is_empty();
    assert_eq!(summary.figures, 19 + flagged as usize);
    for svg in &svgs {
        let svg = &svg[..svg.find("</svg>").expect("closed svg")];
        // Axis titles carry their unit in parentheses: both axes.
        let labelled = svg
            .split("<text")
            .skip(1)
            .filter(|t| t.contains('(') && t.contains(')'))
            .count();
        assert!(labelled >= 2, "a figure without both axis titles");
        assert!(svg.contains("<circle") || svg.contains("<rect"));
    }
    // Nothing fetched: no script, stylesheet link or source; every link
    // inside the page or a data: URL.
    for bad in ["<script", "<link", "<img", "<iframe", "@import", "url("] {
        assert!(!html.contains(bad), "{bad}");
    }
    assert!(attributes(&html, "src").is_empty());
    for href in attributes(&html, "href") {
        assert!(href.starts_with('#') || href.starts_with("data:"), "{href}");
    }

    // The numbers: the model's R² and RMSE in the caption are the fit's own
    // indicators, computed by the fitting code (another route).
    for (label, split_name) in [("Training", "Training"), ("Testing", "testing")] {
        let m = &pca
            .indicators
            .iter()
            .find(|i| i.label == label)
            .unwrap()
            .metrics;
        let text = format!("{split_name} R² {:.3} RMSE {:.2} %", m.r2, m.rmse);
        assert!(html.contains(&text), "{text}");
    }
    // So are the shares of tires inside their 95 % prediction interval,
    // and inside the new-event one (from the fit's leave-one-event-out refits).
    let share = |label: &str, event: bool| {
        let i = pca.indicators.iter().find(|i| i.label == label).unwrap();
        let s = if event {
            i.inside_95_event_interval
        } else {
            i.inside_95_interval
        };
        100.0 * s.unwrap()
    };
    for text in [
        format!(
            "The 95 % prediction intervals hold {:.1} % of the training and {:.1} % of the testing",
            share("Training", false),
            share("Testing", false)
        ),
        format!(
            "their event left out) hold {:.1} % and {:.1} %.",
            share("Training", true),
            share("Testing", true)
        ),
    ] {
        assert!(html.contains(&text), "{text}");
    }
    // Each testing tire's 95 % new-event interval drawn as a whisker under
    // its mark (drawn at opacity 0.35, the report's `WHISKER_OPACITY`), in
    // the rows' order: the half-width by hand as the ⌈0.95 (n + 1)⌉-th
    // smallest of the axle's leave-one-event-out errors, and the whiskers'
    // pixels an affine map of (measured, predicted ± half-width), within the
    // one pixel plotters rounds to.
    let errors = pca.event_errors.as_ref().unwrap();
    let half = |scores: &[f64]| {
        let mut s = scores.to_vec();
        s.sort_by(f64::total_cmp);
        let rank = (0.95 * (s.len() + 1) as f64).ceil() as usize;
        s[rank - 1]
    };
    let (front_half, rear_half) = (half(&errors.front), half(&errors.rear));
    let expected: Vec<(f64, f64, f64)> = rows
        .iter()
        .filter(|r| pca.testing_events.contains(&r.event))
        .filter(|r| r.wear_mean_pct.is_finite() && r.worn_through_readings <= 0.0)
        .filter_map(|r| {
            let p = pca.predict_row(r).ok().filter(|p| p.is_finite())?;
            let h = match r.axle {
                tirewear::Axle::Front => front_half,
                tirewear::Axle::Rear => rear_half,
            };
            Some((r.wear_mean_pct, p - h, p + h))
        })
        .collect();
    let caption = html.find("Predicted against measured wear: pca").unwrap();
    let svg = &html[html[..caption].rfind("<svg").unwrap()..];
    let svg = &svg[..svg.find("</svg>").unwrap()];
    let drawn: Vec<(f64, f64, f64)> = svg
        .split("<polyline")
        .skip(1)
        .filter(|l| l.contains("opacity=\"0.35\""))
        .map(|l| {
            let points = attributes(l, "points")[0];
            let xy: Vec<f64> = points
                .split([' ', ','])
                .filter(|v| !v.is_empty())
                .map(|v| v.parse().unwrap())
                .collect();
            assert_eq!(xy.len(), 4, "{points}");
            assert_eq!(xy[0], xy[2], "a whisker is vertical: {points}");
            (xy[0], xy[1], xy[3])
        })
        .collect();
    assert!(expected.len() >= 40, "{} testing tires", expected.len());
    assert_eq!(drawn.len(), expected.len());
    assert!(html.contains("Whiskers: each testing tire&#39;s 95 % interval for a new event."));
    // Least-squares line of pixels on values; every point within a pixel.
    let zipped = || expected.iter().zip(&drawn);
    let x_pairs: Vec<(f64, f64)> = zipped().map(|(e, d)| (e.0, d.0)).collect();
    let (x_scale, x_worst) = least_squares(&x_pairs);
    let y_pairs: Vec<(f64, f64)> = zipped()
        .flat_map(|(e, d)| [(e.1, d.1), (e.2, d.2)])
        .collect();
    let (y_scale, y_worst) = least_squares(&y_pairs);
    assert!(
        x_scale > 0.0 && x_worst <= 1.0,
        "x: {x_scale} px/%, off by {x_worst} px"
    );
    assert!(
        y_scale < 0.0 && y_worst <= 1.0,
        "y: {y_scale} px/%, off by {y_worst} px"
    );

    // The season's wear by event: each event's rear axle worked out here
    // from the rows (mean, sample sd with n − 1, least, most of the tires
    // not worn through; those worn through counted), against its table row.
    let mut events: Vec<&str> = rows.iter().map(|r| r.event.as_str()).collect();
    events.sort();
    events.dedup();
    for event in &events {
        let tires: Vec<_> = rows
            .iter()
            .filter(|r| r.event == *event && r.axle == tirewear::Axle::Rear)
            .collect();
        let wear: Vec<f64> = tires
            .iter()
            .filter(|r| r.wear_mean_pct.is_finite() && r.worn_through_readings <= 0.0)
            .map(|r| r.wear_mean_pct)
            .collect();
        let n = wear.len() as f64;
        let mean = wear.iter().sum::<f64>() / n;
        let sd = (wear.iter().map(|w| (w - mean) * (w - mean)).sum::<f64>() / (n - 1.0)).sqrt();
        let mut sorted = wear.clone();
        sorted.sort_by(f64::total_cmp);
        let worn = tires
            .iter()
            .filter(|r| r.worn_through_readings > 0.0)
            .count();
        let mut compounds: Vec<&str> = tires.iter().map(|r| r.compound.as_str()).collect();
        compounds.sort();
        compounds.dedup();
        let row = format!(
            "<tr><td class=\"t\">{event}</td><td class=\"t\">{}</td><td class=\"t\">{}</td><td class=\"t\">rear</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{mean:.2}</td><td class=\"n\">{sd:.2}</td><td class=\"n\">{:.2}</td><td class=\"n\">{:.2}</td><td class=\"n\">{worn}</td></tr>",
            tires[0].track,
            compounds.join(" "),
            tires.len(),
            wear.len(),
            sorted[0],
            sorted[sorted.len() - 1]
        );
        assert!(html.contains(&row), "{row}");
    }
    assert!(html.contains("<h3>Wear by event</h3>"));

    // The per-track line of one track and axle against the closed form of
    // least squares (slope = Σ(x−x̄)(y−ȳ) / Σ(x−x̄)²) on the rows.
    let track = rows[0].track.clone();
    let xy: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.track == track && r.axle == tirewear::Axle::Front)
        .filter(|r| r.wear_mean_pct.is_finite() && r.worn_through_readings <= 0.0)
        .map(|r| (r.friction_energy_j / 1e6, r.wear_mean_pct))
        .collect();
    let (slope, _) = least_squares(&xy);
    let cell = format!(
        "<td class=\"t\">{track}</td><td class=\"t\">front</td><td class=\"n\">{}</td><td class=\"n\">{slope:.3}</td>",
        xy.len()
    );
    assert!(html.contains(&cell), "{cell}");
    // The per-track lines of the report (all events) and the physical
    // model's preliminary analysis (its own code, training events) agree
    // where a track raced only in training events (same n); R1 and R2 are
    // in the reliability table.
    let tirewear::model::saved::ModelBody::Physical { front, .. } = &physical.model else {
        panic!("a physical model")
    };
    let mut compared = 0;
    for l in &front.lines {
        let line = format!(
            "<td class=\"t\">{}</td><td class=\"t\">front</td><td class=\"n\">{}</td><td class=\"n\">{:.3}</td>",
            l.track, l.n, l.slope_pct_per_mj
        );
        let report_n = rows
            .iter()
            .filter(|r| r.track == l.track && r.axle == tirewear::Axle::Front)
            .filter(|r| r.wear_mean_pct.is_finite() && r.worn_through_readings <= 0.0)
            .count();
        if report_n == l.n {
            // Twice: the report's table and the reliability table.
            assert_eq!(html.matches(&line).count(), 2, "{line}");
            compared += 1;
        }
        let r1r2 = format!(
            "<td class=\"n\">{:.3}</td><td class=\"n\">{:.3}</td><td class=\"n\">{}</td>",
            l.r1, l.r2, l.n_consistent
        );
        assert!(html.contains(&r1r2), "{r1r2}");
    }
    assert!(compared >= 2, "{compared} tracks compared");
    // The CSV behind the figure holds every tire-run.
    let csv = attributes(&html, "href")
        .into_iter()
        .find(|h| h.starts_with("data:") && percent_decode(h).contains("friction_energy_mj"))
        .map(percent_decode)
        .unwrap();
    assert_eq!(csv.lines().count(), rows.len() + 1);

    // With a `tirewear bench` JSON (written by hand: two lines), a
    // performance section with one more figure and each line's ratio.
    let bench = dir.path().join("my-bench.json");
    std::fs::write(
        &bench,
        r#"{"cpu": "CPU, 2 threads", "gpu": null, "threads": 2, "lines": [
            {"kernel": "energy_map", "size": "1 M samples", "engine": "cpu, 1 thread",
             "seconds": 0.004, "vs_memory_pass": 0.5, "reference": "memory pass"},
            {"kernel": "decode, block", "size": "80 runs", "engine": "tirewear, 1 thread",
             "seconds": 0.3, "vs_memory_pass": 0.73, "reference": "zstd only"}]}"#,
    )
    .unwrap();
    let with =
        tirewear::report::write_report(dir.path(), &out, std::slice::from_ref(&bench)).unwrap();
    assert_eq!(with.sections.last().unwrap(), "Performance");
    assert_eq!(with.figures, summary.figures + 1);
    let html = std::fs::read_to_string(&out).unwrap();
    for cell in [
        "<td class=\"n\">4.00</td>",
        "<td class=\"n\">0.500</td>",
        "<td class=\"n\">0.730</td>",
    ] {
        assert!(html.contains(cell), "{cell}");
    }
    let missing = dir.path().join("nothing.json");
    let e = tirewear::report::write_report(dir.path(), &out, &[missing]).unwrap_err();
    assert!(e.to_string().contains("nothing.json"), "{e}");

    // Two machines' bench files (by hand): the lines both hold side by
    // side, each machine's all-thread line matched whatever its thread
    // count, speeds worked out by hand as the first file's time over the
    // second's; a line only one machine has listed apart.
    let container = dir.path().join("container.json");
    std::fs::write(
        &container,
        r#"{"cpu": "EPYC, 2 threads", "gpu": null, "threads": 2, "lines": [
            {"kernel": "energy_map", "size": "1 M samples", "engine": "cpu, 1 thread",
             "seconds": 0.004, "vs_memory_pass": 0.5, "reference": "memory pass"},
            {"kernel": "energy_map", "size": "1 M samples", "engine": "cpu, 2 threads",
             "seconds": 0.0025, "vs_memory_pass": 0.8, "reference": "memory pass"},
            {"kernel": "decode, block", "size": "80 runs", "engine": "zstd only, 2 thr",
             "seconds": 0.3, "vs_memory_pass": 1.0, "reference": "zstd only"}]}"#,
    )
    .unwrap();
    let h200 = dir.path().join("h200.json");
    std::fs::write(
        &h200,
        r#"{"cpu": "Xeon, 16 threads", "gpu": "NVIDIA H200", "threads": 16, "lines": [
            {"kernel": "energy_map", "size": "1 M samples", "engine": "cpu, 1 thread",
             "seconds": 0.005, "vs_memory_pass": 0.4, "reference": "memory pass"},
            {"kernel": "energy_map", "size": "1 M samples", "engine": "cpu, 16 threads",
             "seconds": 0.0005, "vs_memory_pass": 2.0, "reference": "memory pass"},
            {"kernel": "energy_map", "size": "1 M samples", "engine": "gpu",
             "seconds": 0.0001, "vs_memory_pass": 9.0, "reference": "memory pass"},
            {"kernel": "decode, block", "size": "80 runs", "engine": "zstd only, 16 thr",
             "seconds": 0.25, "vs_memory_pass": 1.0, "reference": "zstd only"}]}"#,
    )
    .unwrap();
    let both = tirewear::report::write_report(dir.path(), &out, &[container, h200]).unwrap();
    // The comparison, then each machine's own figure.
    assert_eq!(both.figures, summary.figures + 3);
    let html = std::fs::read_to_string(&out).unwrap();
    let performance = &html[html.rfind("Performance</h2>").unwrap()..];
    for cell in [
        "<th>container (ms)</th><th>h200 (ms)</th><th>h200 vs container</th>",
        // 1 thread: 4 ms against 5 ms, 0.004 / 0.005.
        "<td class=\"t\">cpu, 1 thread</td><td class=\"n\">4.00</td><td class=\"n\">5.00</td><td class=\"n\">0.800</td>",
        // All threads: 2.5 ms on 2, 0.5 ms on 16, 0.0025 / 0.0005.
        "<td class=\"t\">cpu, all threads</td><td class=\"n\">2.50</td><td class=\"n\">0.50</td><td class=\"n\">5.000</td>",
        "<td class=\"t\">zstd only, all threads</td><td class=\"n\">300.00</td><td class=\"n\">250.00</td><td class=\"n\">1.200</td>",
        "Only in h200 (not compared): energy_map (1 M samples, gpu).",
        "<h3>container</h3>",
        "<h3>h200</h3>",
        "GPU: NVIDIA H200.",
    ] {
        assert!(performance.contains(cell), "{cell}");
    }
    // The legend names both files (plotters writes text on its own line).
    for label in ["container", "h200"] {
        assert!(
            performance.contains(&format!(">\n{label}\n</text>")),
            "{label}"
        );
    }
    // A JSON that is not a bench file is refused by name.
    let other = dir.path().join("models.json");
    std::fs::write(&other, r#"{"method": "pca"}"#).unwrap();
    let e = tirewear::report::write_report(dir.path(), &out, &[other]).unwrap_err();
    assert!(
        e.to_string().contains("models.json") && e.to_string().contains("lines"),
        "{e}"
    );
}

#[test]
fn a_folder_without_kpis_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let e =
        tirewear::report::write_report(dir.path(), &dir.path().join("r.html"), &[]).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("kpis.parquet") && msg.contains("tirewear extract"),
        "{msg}"
    );
    assert!(!dir.path().join("r.html").exists());
}

/// One damaged optional input costs its own figures, not the page: a model
/// with a changed digit, a road table with a flipped byte, a gap file that
/// is not JSON and one compound file that is not TOML are each named at the top of the page and left out; the
/// rest is drawn, and the command exits 3.
#[test]
fn damaged_optional_inputs_are_named_and_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let rows = common::demo_kpis(dir.path());
    let s = split(&rows, None).unwrap();
    let settings = FitSettings::default();
    let (pca, _) = fit_method(Method::Pca, &s, &settings).unwrap();
    let (physical, _) = fit_method(Method::Physical, &s, &settings).unwrap();
    let models = dir.path().join("models");
    save_all(&[pca, physical], &models).unwrap();
    // A legend's compound names in the clean page (plotters writes a
    // label's text on its own line).
    let out = dir.path().join("report.html");
    tirewear::report::write_report(dir.path(), &out, &[]).unwrap();
    let legends = |page: &str, id: &str| page.matches(&format!("\n{id}\n</text>")).count();
    let clean = std::fs::read_to_string(&out).unwrap();
    assert!(legends(&clean, "hard") > 0 && legends(&clean, "medium") > 0);

    let model = models.join("physical.json");
    let text = std::fs::read_to_string(&model).unwrap();
    // A digit of the coefficients, past the format's version.
    let after = text.find("\"features\"").unwrap();
    let digit = after
        + text[after..]
            .find(|c: char| c.is_ascii_digit() && c != '0')
            .unwrap();
    let mut damaged = text.into_bytes();
    damaged[digit] = if damaged[digit] == b'9' {
        b'8'
    } else {
        damaged[digit] + 1
    };
    std::fs::write(&model, damaged).unwrap();
    let road = dir.path().join("kpis.road.parquet");
    let mut bytes = std::fs::read(&road).unwrap();
    let at = bytes.len() / 3;
    bytes[at] ^= 0x10;
    std::fs::write(&road, bytes).unwrap();
    std::fs::create_dir_all(dir.path().join("gap")).unwrap();
    std::fs::write(dir.path().join("gap/gap.json"), "{\"slices\": [").unwrap();
    std::fs::write(dir.path().join("compounds/hard.toml"), "id = [").unwrap();

    let summary = tirewear::report::write_report(dir.path(), &out, &[]).unwrap();
    assert_eq!(summary.left_out.len(), 4, "{:?}", summary.left_out);
    for name in [
        "physical.json",
        "kpis.road.parquet",
        "gap.json",
        "hard.toml",
    ] {
        assert!(
            summary.left_out.iter().any(|e| e.contains(name)),
            "{name}: {:?}",
            summary.left_out
        );
    }
    let page = std::fs::read_to_string(&out).unwrap();
    assert!(page.contains("These inputs could not be read"));
    assert!(
        page.contains("data_crc32"),
        "the model's checksum named: {:?}",
        summary.left_out
    );
    // The PCA model and the other compounds' curves are still shown; every
    // section is still on the page.
    assert!(page.contains("pca.json"));
    assert_eq!(legends(&page, "hard"), 0);
    assert_eq!(legends(&page, "medium"), legends(&clean, "medium"));
    assert_eq!(summary.sections.len(), 7, "{:?}", summary.sections);

    let exe = env!("CARGO_BIN_EXE_tirewear");
    let run = std::process::Command::new(exe)
        .args(["--quiet", "--log", "error", "report"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(3));
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(text.contains("left out: "), "{text}");
}
