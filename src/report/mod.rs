//! `report.html`: one self-contained page per season with the paper's
//! figures (docs/report.md). Reads what `extract`, `fit` and `gap` wrote in
//! a season folder — `kpis.parquet` (required), `kpis.report.json`,
//! `models/*.json`, `gap/gap.json` (each optional: a section whose input is
//! missing says which command writes it) — and draws every figure as inline
//! SVG, its numbers beside it as a table or an inline CSV download. Nothing
//! is fetched: no script, font, style or image from anywhere.

pub mod error;
mod figure;
mod html;
mod sections;

pub use error::ReportError;
use std::path::{Path, PathBuf};

/// What was written.
#[derive(Debug, Clone)]
pub struct ReportSummary {
    pub path: PathBuf,
    /// Section titles, in page order.
    pub sections: Vec<String>,
    pub figures: usize,
    /// What the page lacks, each with why: optional inputs that could not
    /// be read (their file and what was wrong, also listed at the top of
    /// the page) and sections that could not be drawn (said in their place).
    pub left_out: Vec<String>,
}

/// The season folder's inputs, read once.
pub(crate) struct Inputs {
    pub dir: PathBuf,
    pub rows: Vec<crate::kpi::KpiRow>,
    pub extraction: Option<serde_json::Value>,
    pub models: Vec<(PathBuf, crate::model::saved::SavedModel)>,
    pub gap: Option<serde_json::Value>,
    /// `kpis.road.parquet`: PSD and HDC curves per track and location.
    pub road: Vec<crate::kpi::extract::RoadCurvePoint>,
    /// `kpis.energy_maps.parquet`: each tire-run's friction-energy maps.
    pub maps: std::collections::BTreeMap<crate::kpi::TireRun, crate::kpi::energy_maps::EnergyMaps>,
    /// `compounds/*.toml`: the master curves.
    pub compounds: Vec<crate::ingest::compound::Compound>,
    /// The `tirewear bench` JSONs given, or the folder's `bench.json`: one
    /// machine's lines each; two or more are compared line by line.
    pub bench: Vec<BenchFile>,
    /// Optional inputs that exist but could not be read (damaged, another
    /// extraction's): each named at the top of the page and left out, so
    /// that one bad file costs its own figures, not the report.
    pub unread: Vec<ReportError>,
}

/// One `tirewear bench` JSON and the name the report gives it.
pub(crate) struct BenchFile {
    /// The file's name without `.json` (its folder too where two files
    /// share a name): what the comparison's legend and columns say.
    pub label: String,
    pub json: serde_json::Value,
}

/// Reads the bench files, each checked to hold a `lines` array, and names
/// them by their stems (with the folder where two stems are alike).
fn read_bench_files(paths: &[PathBuf]) -> Result<Vec<BenchFile>, ReportError> {
    let mut files = Vec::with_capacity(paths.len());
    for path in paths {
        let Some(json) = read_json(path)? else {
            return Err(ReportError::Input {
                path: path.clone(),
                message: "not found (a `tirewear bench` JSON was asked for)".into(),
            });
        };
        if !json["lines"].is_array() {
            return Err(ReportError::Input {
                path: path.clone(),
                message: "not a `tirewear bench` JSON: it has no `lines` array".into(),
            });
        }
        files.push(BenchFile {
            label: String::new(),
            json,
        });
    }
    let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().into_owned());
    let stems: Vec<String> = paths
        .iter()
        .map(|p| stem(p).unwrap_or_else(|| "bench".into()))
        .collect();
    for (i, f) in files.iter_mut().enumerate() {
        let alike = stems.iter().filter(|s| **s == stems[i]).count() > 1;
        let folder = paths[i].parent().and_then(stem).filter(|_| alike);
        f.label = match folder {
            Some(folder) => format!("{folder}/{}", stems[i]),
            None => stems[i].clone(),
        };
    }
    // Still alike (the same folder names): numbered in the given order.
    for i in 0..files.len() {
        if files[..i].iter().any(|f| f.label == files[i].label) {
            files[i].label = format!("{} ({})", files[i].label, i + 1);
        }
    }
    Ok(files)
}

fn read_json(path: &Path) -> Result<Option<serde_json::Value>, ReportError> {
    if !path.exists() {
        return Ok(None);
    }
    let input = |message: String| ReportError::Input {
        path: path.into(),
        message,
    };
    let text = crate::ingest::read_text(path, crate::ingest::MAX_JSON_BYTES)
        .map_err(|e| ReportError::input(path, e))?;
    let head = serde_json::from_str(&text).map_err(|e| input(format!("not valid JSON: {e}")))?;
    match crate::ingest::checksum::json_mismatch(&text, &head, "tirewear") {
        Some(why) => Err(input(why)),
        None => Ok(Some(head)),
    }
}

/// `r`'s value, or `None` with its error kept in `unread` (and logged).
fn optional<T>(r: Result<T, ReportError>, unread: &mut Vec<ReportError>) -> Option<T> {
    r.map_err(|e| {
        tracing::warn!("left out of the report: {e}");
        unread.push(e)
    })
    .ok()
}

/// The folder under `dir/sub` whose files the report shows: `dir/sub`
/// itself when it holds any of `names` (a season folder after `fit`/`gap`),
/// else the newest dated subfolder that does (`tirewear process --then
/// fit,gap` writes `models/2026-11-24T023000Z/…`; other subfolders are
/// not results and are passed over). One folder for all the names, so that
/// the models shown come from one fit: a method that failed last night is
/// missing, not an older night's.
fn newest(dir: &Path, sub: &str, names: &[&str]) -> PathBuf {
    use crate::nightly::stamp::{is_stamp, time_order};
    let holds = |d: &Path| names.iter().any(|n| d.join(n).exists());
    let direct = dir.join(sub);
    if holds(&direct) {
        return direct;
    }
    let dated = std::fs::read_dir(&direct)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| is_stamp(n) && holds(&direct.join(n)))
        .max_by_key(|n| time_order(n));
    dated.map_or(direct.clone(), |n| direct.join(n))
}

/// The compound folders of a season folder, or of the archives a `process`
/// dataset was built from (its `dataset.json`).
fn compound_dirs(dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let own = dir.join("compounds");
    if own.is_dir() {
        return Ok(vec![own]);
    }
    let Some(dataset) = read_json(&dir.join("dataset.json"))? else {
        return Ok(Vec::new());
    };
    Ok(dataset["archives"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|a| a.as_str())
        .map(|a| Path::new(a).join("compounds"))
        .filter(|p| p.is_dir())
        .collect())
}

impl Inputs {
    pub fn read(dir: &Path, bench: &[PathBuf]) -> Result<Inputs, ReportError> {
        let kpis = dir.join("kpis.parquet");
        if !kpis.exists() {
            return Err(ReportError::Input {
                path: kpis,
                message: "missing: run `tirewear extract` on the season first".into(),
            });
        }
        let rows =
            crate::kpi::table::read_parquet(&kpis).map_err(|e| ReportError::input(&kpis, e))?;
        let mut unread = Vec::new();
        let mut models = Vec::new();
        const MODEL_FILES: [&str; 3] = ["physical.json", "pca.json", "ffnn.json"];
        let fit = newest(dir, "models", &MODEL_FILES);
        for name in MODEL_FILES {
            let path = fit.join(name);
            if path.exists() {
                let m = crate::model::saved::SavedModel::load(&path)
                    .map_err(|e| ReportError::input(&path, e));
                models.extend(optional(m, &mut unread).map(|m| (path, m)));
            }
        }
        let side = |suffix: &str| crate::kpi::table::side_table_path(&kpis, suffix);
        let input =
            |path: PathBuf| move |e: crate::ingest::IngestError| ReportError::input(&path, e);
        let road_path = side("road.parquet");
        let road = if road_path.exists() {
            optional(
                crate::kpi::extract::read_road_curves(&road_path).map_err(input(road_path.clone())),
                &mut unread,
            )
            .unwrap_or_default()
        } else {
            Vec::new()
        };
        let maps_path = side("energy_maps.parquet");
        let maps = if maps_path.exists() {
            optional(
                crate::kpi::table::check_same_extraction(&kpis, &maps_path)
                    .and_then(|()| crate::kpi::energy_maps::read_energy_maps(&maps_path))
                    .map_err(input(maps_path)),
                &mut unread,
            )
            .unwrap_or_default()
        } else {
            Default::default()
        };
        let mut compounds: Vec<crate::ingest::compound::Compound> = Vec::new();
        // Each compound file on its own: a damaged one costs only its curve.
        for d in optional(compound_dirs(dir), &mut unread).unwrap_or_default() {
            let files = crate::ingest::compound::compound_files(&d).map_err(input(d.clone()));
            for f in optional(files, &mut unread).unwrap_or_default() {
                let read = crate::ingest::compound::Compound::load(&f).map_err(input(f.clone()));
                if let Some(c) = optional(read, &mut unread)
                    && !compounds.iter().any(|k| k.id == c.id)
                {
                    compounds.push(c);
                }
            }
        }
        // Bench files asked for on the command line are not optional.
        let default_bench = dir.join("bench.json");
        let bench = match bench {
            [] if default_bench.exists() => {
                optional(read_bench_files(&[default_bench]), &mut unread).unwrap_or_default()
            }
            [] => Vec::new(),
            paths => read_bench_files(paths)?,
        };
        // A season's extraction report, or a `process` dataset's summary.
        let extraction =
            match optional(read_json(&dir.join("kpis.report.json")), &mut unread).flatten() {
                Some(r) => Some(r),
                None => optional(read_json(&dir.join("summary.json")), &mut unread).flatten(),
            };
        let gap = optional(
            read_json(&newest(dir, "gap", &["gap.json"]).join("gap.json")),
            &mut unread,
        )
        .flatten();
        Ok(Inputs {
            bench,
            compounds,
            road,
            maps,
            dir: dir.into(),
            rows,
            extraction,
            models,
            gap,
            unread,
        })
    }
}

/// One section of the page: its title and HTML, and how many figures.
pub(crate) struct Section {
    pub title: String,
    pub html: String,
    pub figures: usize,
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em;color:#222}\
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}\
figure{margin:1em 0;page-break-inside:avoid}figure svg{max-width:100%;height:auto}\
figcaption{font-size:.9em;color:#444;margin:.3em 0}\
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}\
td,th{border:1px solid #ddd;padding:2px 6px;text-align:left}th{background:#f4f4f4}\
td.n{text-align:right;font-variant-numeric:tabular-nums}a.csv{font-size:.85em}\
p.missing{color:#a33}@media print{a.csv{display:none}}";

/// A section that could not be drawn says so in its place (and in
/// `not_drawn`), so one figure's failure costs that section, not the page.
fn drawn(title: &str, s: Result<Section, ReportError>, not_drawn: &mut Vec<String>) -> Section {
    s.unwrap_or_else(|e| {
        tracing::warn!("report section {title}: {e}");
        not_drawn.push(format!("section {title}: could not be drawn: {e}"));
        Section {
            title: title.into(),
            html: format!(
                "<p class=\"missing\">This section could not be drawn: {}</p>\n",
                html::escape(&e.to_string())
            ),
            figures: 0,
        }
    })
}

/// The whole page, and the sections that could not be drawn (each with why).
pub(crate) fn render(inputs: &Inputs) -> (String, Vec<Section>, Vec<String>) {
    let mut not_drawn = Vec::new();
    let mut sections = vec![sections::season(inputs)];
    for (title, s) in [
        ("Road", sections::road(inputs)),
        ("Viscoelastic", sections::viscoelastic(inputs)),
        ("Telemetry", sections::telemetry(inputs)),
        ("Physical correlations", sections::physical(inputs)),
        ("Wear models", sections::models(inputs)),
        ("Sim-to-real gap", sections::gap(inputs)),
    ] {
        sections.push(drawn(title, s, &mut not_drawn));
    }
    match sections::performance(inputs) {
        Ok(p) => sections.extend(p),
        Err(e) => sections.push(drawn("Performance", Err(e), &mut not_drawn)),
    }
    let name = inputs
        .dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "season".into());
    let mut page = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
<title>tirewear report: {0}</title><style>{STYLE}</style></head><body>\n\
<h1>Tire-wear report: {0}</h1>\n<p>Written by tirewear {1} from the season folder's \
outputs. Figures mirror the paper's; definitions in docs/report.md and docs/kpis.md.</p>\n<nav><ol>",
        html::escape(&name),
        env!("CARGO_PKG_VERSION")
    );
    for (i, s) in sections.iter().enumerate() {
        page += &format!(
            "<li><a href=\"#s{}\">{}</a></li>",
            i + 1,
            html::escape(&s.title)
        );
    }
    page += "</ol></nav>\n";
    if !inputs.unread.is_empty() {
        page += "<p class=\"missing\">These inputs could not be read and are left out; \
the sections that need them say their input is missing:</p>\n<ul>";
        for e in &inputs.unread {
            page += &format!("<li>{}</li>", html::escape(&e.to_string()));
        }
        page += "</ul>\n";
    }
    for (i, s) in sections.iter().enumerate() {
        page += &format!(
            "<section id=\"s{}\"><h2>{}. {}</h2>\n{}</section>\n",
            i + 1,
            i + 1,
            html::escape(&s.title),
            s.html
        );
    }
    page += "</body></html>\n";
    (page, sections, not_drawn)
}

/// Writes `out` (atomically) from the season folder `dir`, with the
/// performance section from `bench` (`tirewear bench` JSONs, one per
/// machine, compared line by line when there are two or more; none given:
/// `dir/bench.json` when it exists).
pub fn write_report(
    dir: &Path,
    out: &Path,
    bench: &[PathBuf],
) -> Result<ReportSummary, ReportError> {
    check_season_folder(dir)?;
    check_page_destination(out)?;
    let inputs = Inputs::read(dir, bench)?;
    let (page, sections, not_drawn) = render(&inputs);
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| ReportError::Io {
            path: parent.into(),
            source,
        })?;
    }
    crate::atomic::write_bytes(out, page.as_bytes()).map_err(|source| ReportError::Io {
        path: out.into(),
        source,
    })?;
    Ok(ReportSummary {
        path: out.into(),
        figures: sections.iter().map(|s| s.figures).sum(),
        sections: sections.into_iter().map(|s| s.title).collect(),
        left_out: inputs
            .unread
            .iter()
            .map(ToString::to_string)
            .chain(not_drawn)
            .collect(),
    })
}

/// The report reads a folder: given a file (the KPI table, most likely),
/// it names the folder that holds it.
fn check_season_folder(dir: &Path) -> Result<(), ReportError> {
    if !dir.is_file() {
        return Ok(());
    }
    let parent = crate::atomic::folder_of(dir);
    Err(ReportError::Input {
        path: dir.into(),
        message: format!(
            "is a file: the report takes the folder that holds kpis.parquet (a season or \
             a dataset), such as {}",
            parent.display()
        ),
    })
}

/// Refuses, before anything is read, a destination the page would wrongly
/// replace: a folder, or a file that is no HTML page (the KPI table, a
/// model or `gap.json` given as `--out` by mistake). A page written before
/// is replaced.
fn check_page_destination(out: &Path) -> Result<(), ReportError> {
    crate::atomic::check_replaceable(out, "report", &[], "an HTML page", |head| {
        if head.is_empty() || is_html(head) {
            Ok(())
        } else {
            Err(crate::ingest::checksum::what_it_is(head))
        }
    })
    .map_err(|c| ReportError::Output {
        path: out.into(),
        message: c.reason,
    })
}

/// Whether a file's first bytes begin an HTML page (`<!DOCTYPE html` or
/// `<html`, in any case, after a byte-order mark and white space).
fn is_html(head: &[u8]) -> bool {
    let head = head.strip_prefix(b"\xef\xbb\xbf").unwrap_or(head);
    let start = head
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(head.len());
    let head = head[start..].to_ascii_lowercase();
    head.starts_with(b"<!doctype html") || head.starts_with(b"<html")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pages as browsers and tirewear write them are HTML; data is not.
    #[test]
    fn an_html_page_is_told_from_data_by_its_first_bytes() {
        for page in [
            &b"<!DOCTYPE html>\n<html>"[..],
            b"\xef\xbb\xbf  \n<!doctype HTML>",
            b"<HTML lang=en>",
        ] {
            assert!(is_html(page), "{}", String::from_utf8_lossy(page));
        }
        for data in [
            &b"PAR1"[..],
            b"{\"html\": 1}",
            b"format_version = 1",
            b"<?xml version",
            b"\x89MCAP",
        ] {
            assert!(!is_html(data), "{}", String::from_utf8_lossy(data));
        }
    }

    /// A FIFO where the page goes is not opened to see what it is (the
    /// open would wait for a writer): the rename replaces it.
    #[cfg(unix)]
    #[test]
    fn a_fifo_as_the_page_is_not_opened() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("report.html");
        crate::make_fifo(&fifo);
        assert!(check_page_destination(&fifo).is_ok());
    }

    #[test]
    fn newest_takes_the_direct_folder_else_the_latest_dated_one() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let both = ["pca.json", "ffnn.json"];
        for stamp in ["2026-11-23T0230Z", "2026-11-24T0230Z", "2026-11-22T0230Z"] {
            std::fs::create_dir_all(d.join("models").join(stamp)).unwrap();
            std::fs::write(d.join("models").join(stamp).join("pca.json"), "{}").unwrap();
        }
        // A later folder without the files does not count.
        std::fs::create_dir_all(d.join("models/2026-11-25T0230Z")).unwrap();
        assert_eq!(
            newest(d, "models", &both),
            d.join("models/2026-11-24T0230Z")
        );
        // A later fit that wrote only one of them is the one shown: the
        // other is missing, not taken from an older fit.
        std::fs::create_dir_all(d.join("models/2026-11-26T0230Z")).unwrap();
        std::fs::write(d.join("models/2026-11-26T0230Z/ffnn.json"), "{}").unwrap();
        assert_eq!(
            newest(d, "models", &both),
            d.join("models/2026-11-26T0230Z")
        );
        // Seconds stamps order in time with the older minute ones (a plain
        // string order puts this one before the minute it follows), and a
        // folder not named like a stamp is not a result.
        for name in ["2026-11-26T023001Z", "zz-kept-by-hand"] {
            std::fs::create_dir_all(d.join("models").join(name)).unwrap();
            std::fs::write(d.join("models").join(name).join("pca.json"), "{}").unwrap();
        }
        assert_eq!(
            newest(d, "models", &both),
            d.join("models/2026-11-26T023001Z")
        );
        std::fs::write(d.join("models/pca.json"), "{}").unwrap();
        assert_eq!(newest(d, "models", &both), d.join("models"));
        // Nothing at all: the direct folder, which does not exist.
        assert_eq!(newest(d, "gap", &["gap.json"]), d.join("gap"));
    }

    #[test]
    fn bench_files_are_named_by_stem_with_their_folder_where_alike() {
        let dir = tempfile::tempdir().unwrap();
        let write = |rel: &str| {
            let p = dir.path().join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(&p, r#"{"lines": []}"#).unwrap();
            p
        };
        let paths = [
            write("h200/bench.json"),
            write("laptop/bench.json"),
            write("ci.json"),
            write("x/h200/bench.json"),
        ];
        let labels: Vec<String> = read_bench_files(&paths)
            .unwrap()
            .into_iter()
            .map(|f| f.label)
            .collect();
        assert_eq!(
            labels,
            ["h200/bench", "laptop/bench", "ci", "h200/bench (4)"]
        );
    }

    /// `gap.json` and `kpis.report.json` as tirewear writes them are read;
    /// a digit changed in one is refused naming the file and the checksum;
    /// a file without the checksum (older, or edited with it deleted) is read.
    #[test]
    fn a_changed_digit_in_a_json_input_is_refused_by_its_checksum() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gap.json");
        let body = serde_json::to_string_pretty(&serde_json::json!({"rmse_pct": 12.5})).unwrap();
        let sealed = crate::ingest::checksum::seal_json(&body);
        std::fs::write(&path, &sealed).unwrap();
        assert_eq!(read_json(&path).unwrap().unwrap()["rmse_pct"], 12.5);
        std::fs::write(&path, sealed.replace("12.5", "13.5")).unwrap();
        let e = read_json(&path).unwrap_err().to_string();
        assert!(e.contains("gap.json") && e.contains("data_crc32"), "{e}");
        std::fs::write(&path, body.replace("12.5", "13.5")).unwrap();
        assert_eq!(read_json(&path).unwrap().unwrap()["rmse_pct"], 13.5);
    }

    /// A folder with nothing but this gap.json.
    fn with_gap(gap: serde_json::Value) -> Inputs {
        Inputs {
            dir: "season".into(),
            rows: Vec::new(),
            extraction: None,
            models: Vec::new(),
            gap: Some(gap),
            road: Vec::new(),
            maps: Default::default(),
            compounds: Vec::new(),
            bench: Vec::new(),
            unread: Vec::new(),
        }
    }

    /// A section whose figure fails is replaced by a note saying why; the
    /// page keeps its place and title, and the failure is listed.
    #[test]
    fn a_section_that_cannot_be_drawn_says_so_in_its_place() {
        let mut not_drawn = Vec::new();
        let s = drawn(
            "Road",
            Err(ReportError::Figure("axis range <NaN>".into())),
            &mut not_drawn,
        );
        assert_eq!(s.title, "Road");
        assert_eq!(s.figures, 0);
        assert_eq!(
            s.html,
            "<p class=\"missing\">This section could not be drawn: drawing a figure: axis range &lt;NaN&gt;</p>\n"
        );
        assert_eq!(
            not_drawn,
            ["section Road: could not be drawn: drawing a figure: axis range <NaN>"]
        );
    }

    #[test]
    fn a_malformed_gap_file_renders_without_panicking() {
        // Slices with an empty or missing interval, non-numeric fields,
        // steps without slices, terms without their parts: every figure is
        // still drawn, missing numbers shown as "–".
        let inputs = with_gap(serde_json::json!({
            "slices": [
                {"name": "a", "n": 3, "difference_pct": 1.0, "ci_pct": []},
                {"name": 7, "difference_pct": "x"}
            ],
            "candidates": [{"name": null}],
            "steps": [{"added": "baseline"}, {"added": "t", "training": {"rmse_pct": 1.0}}],
            "terms_wear": [{"run": "r", "wheel": "FL", "by_term_pct": []}],
            "final_terms": []
        }));
        let s = sections::gap(&inputs).unwrap();
        assert_eq!(s.figures, 2, "the slices' bars and the shrink chart");
        assert!(s.html.contains("<td class=\"n\">–</td>"));
    }

    /// The diagnosis's findings in words, each line a paragraph, escaped.
    #[test]
    fn the_gap_section_shows_the_findings_in_words() {
        let inputs = with_gap(serde_json::json!({
            "findings": [
                "1. Energy with slip_ratio above 0.07 abrades 2.30 times the law's rate",
                "Not explained by any term: wheel = FR & t < 80"
            ]
        }));
        let s = sections::gap(&inputs).unwrap();
        assert!(s.html.contains(
            "<h3>Findings</h3>\n<p>1. Energy with slip_ratio above 0.07 abrades 2.30 times the law&#39;s rate</p>\n<p>Not explained by any term: wheel = FR &amp; t &lt; 80</p>"
        ), "{}", s.html);
    }

    #[test]
    fn a_process_summary_lists_its_failed_runs() {
        let inputs = Inputs {
            dir: "season".into(),
            rows: Vec::new(),
            extraction: Some(serde_json::json!({
                "failed": [
                    {"run": "E01-car1-R2", "season": "s", "reason": "CRC mismatch in chunk 3"},
                    {"run": "E02-car1-R1", "season": "s", "reason": "cut short", "kept": true}
                ]
            })),
            models: Vec::new(),
            gap: None,
            road: Vec::new(),
            maps: Default::default(),
            compounds: Vec::new(),
            bench: Vec::new(),
            unread: Vec::new(),
        };
        let s = sections::season(&inputs);
        assert!(s.html.contains("Failed runs (2)"), "{}", s.html);
        assert!(s.html.contains("E01-car1-R2") && s.html.contains("CRC mismatch in chunk 3"));
        // A record without `kept` (before 2026-12-02) has no rows kept.
        assert!(
            s.html
                .contains("<td class=\"t\">CRC mismatch in chunk 3</td><td class=\"t\">none</td>")
                && s.html.contains(
                    "<td class=\"t\">cut short</td><td class=\"t\">the last commit&#39;s</td>"
                ),
            "{}",
            s.html
        );
    }
}
