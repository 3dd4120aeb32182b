//! glibc's allocator tuned for extraction's allocation pattern.
//!
//! Every run allocates its decoded channels, cleaned samples and map buffers
//! afresh (tens of MB a run at 20 Hz) and frees them at the run's end. With
//! glibc's defaults, blocks of that size are mapped and unmapped (or the
//! heap's top trimmed) run after run, so every run pays again for zeroed
//! pages: on the demo season (80 runs, one job) 160 000 page faults and
//! 0.3 s of kernel time in 1.6 s. Keeping blocks up to 32 MB on the heap and
//! trimming only above 256 MB free lets the next run reuse the pages: 1.57
//! → 1.30 s on one job, 0.87 → 0.73 s on two, at 82 → 90 MB (one job) and
//! 94 → 127 MB (two) peak memory (docs/performance.md, "Allocator"). Blocks
//! above 32 MB (200 Hz runs) are still mapped, so the retained memory stays
//! bounded.
//!
//! A user's own `MALLOC_MMAP_THRESHOLD_` / `MALLOC_TRIM_THRESHOLD_`
//! (glibc's tunables) win: with either set, nothing is changed; so does
//! `TIREWEAR_MALLOC_DEFAULTS=1`, which keeps glibc's defaults (to compare).

/// Blocks at most this big come from the heap, not their own mapping.
const MMAP_THRESHOLD_BYTES: i32 = 32 << 20;
/// Free memory at the heap's top returned to the system above this.
const TRIM_THRESHOLD_BYTES: i32 = 256 << 20;

/// Applies the settings; call once, before any thread starts.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub(crate) fn tune() {
    let user_set = [
        "MALLOC_MMAP_THRESHOLD_",
        "MALLOC_TRIM_THRESHOLD_",
        "TIREWEAR_MALLOC_DEFAULTS",
    ]
    .iter()
    .any(|v| std::env::var_os(v).is_some());
    if user_set {
        return;
    }
    // SAFETY: mallopt only sets allocator parameters; it is called from
    // `main` before any other thread exists.
    let ok = unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
            && libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    };
    if !ok {
        tracing::debug!("mallopt refused the allocator settings; glibc's defaults stay");
    }
}

/// Other platforms keep their allocator's defaults.
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub(crate) fn tune() {}
