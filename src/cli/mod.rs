//! The subcommands, one module each: its arguments (clap) and what it
//! runs. The library (`tirewear`) knows nothing of the command line; `main`
//! only parses and maps the outcome to an exit code.

pub(crate) mod allocator;
pub(crate) mod bench;
pub(crate) mod demo;
pub(crate) mod device_select;
pub(crate) mod extract;
pub(crate) mod fit;
pub(crate) mod gap;
pub(crate) mod import;
pub(crate) mod predict;
pub(crate) mod process;
pub(crate) mod report;
pub(crate) mod simulate;

/// Most worker threads `--jobs` takes: far above any machine's cores here;
/// `--jobs 100000` once spent minutes creating threads.
pub(crate) const MAX_JOBS: usize = 1024;

/// `--memory-limit SIZE`: `auto` or a size (`tirewear::memory::MemoryLimit`).
pub(crate) fn parse_memory_limit(s: &str) -> Result<tirewear::memory::MemoryLimit, String> {
    s.parse()
}

/// `--jobs N`: 1 to [`MAX_JOBS`] worker threads.
pub(crate) fn parse_jobs(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=MAX_JOBS).contains(&n) => Ok(n),
        _ => Err(format!("'{s}': worker threads are 1 to {MAX_JOBS}")),
    }
}

/// Refuses an output folder `out` that is a file or lies inside one, before
/// the work rather than after it (a diagnosis or a validation may take
/// minutes), naming the command (`writer`) that writes there.
pub(crate) fn not_a_file(out: &std::path::Path, writer: &str) -> anyhow::Result<()> {
    if out.exists() && !out.is_dir() {
        anyhow::bail!(
            "{}: is a file, not a folder: {writer} writes its files into a folder; give a folder's path",
            out.display()
        );
    }
    if let Some(file) = tirewear::atomic::file_above(out) {
        anyhow::bail!(
            "{}: is inside {}, which is a file, not a folder: {writer} cannot make its folder there",
            out.display(),
            file.display()
        );
    }
    Ok(())
}

/// [`not_a_file`], then makes the folder.
pub(crate) fn output_folder(out: &std::path::Path, writer: &str) -> anyhow::Result<()> {
    not_a_file(out, writer)?;
    anyhow::Context::with_context(std::fs::create_dir_all(out), || {
        format!("creating {}", out.display())
    })
}
