//! `tirewear report`: its arguments and what it runs.

use anyhow::Result;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub(crate) struct ReportArgs {
    /// Season folder after `tirewear extract` (its `kpis.parquet`), and
    /// optionally `fit` (`models/`) and `gap` (`gap/gap.json`); or a
    /// `tirewear process` dataset (the newest dated models and gap).
    dir: PathBuf,
    /// Where to write the page (default DIR/report.html).
    #[arg(long)]
    out: Option<PathBuf>,
    /// A `tirewear bench` JSON for the performance section (default
    /// DIR/bench.json when it exists; without one the section is left out).
    /// Give it once per machine (`--bench h200.json --bench laptop.json`)
    /// to compare them: each line's time on every machine and its speed
    /// against the first file's.
    #[arg(long, value_name = "FILE")]
    bench: Vec<PathBuf>,
}

/// Writes the report of `dir` to `out` and says where it is; false when
/// some optional inputs could not be read and were left out (named).
pub(crate) fn run_report(dir: &Path, out: &Path, bench: &[PathBuf]) -> Result<bool> {
    let s = tirewear::report::write_report(dir, out, bench)?;
    println!(
        "wrote {} ({} figures; sections: {})",
        s.path.display(),
        s.figures,
        s.sections.join(", ")
    );
    for e in &s.left_out {
        println!("left out: {e}");
    }
    Ok(s.left_out.is_empty())
}

/// Runs `tirewear report`; false when some inputs were left out.
pub(crate) fn run(a: ReportArgs) -> Result<bool> {
    let out = a.out.unwrap_or_else(|| a.dir.join("report.html"));
    run_report(&a.dir, &out, &a.bench)
}
