//! The memory a batch of runs may hold at once (docs/reliability.md,
//! "Memory"). A run's decoded telemetry grows with its length: at 1 kHz an
//! hour-long stint needs some 2 GB, so a many-core machine decoding one
//! such run per core, or a small one decoding a six-hour log, would be
//! killed by the kernel (or abort on a failed allocation) and lose every
//! run of the night. Runs are admitted while their estimated needs fit the
//! budget; a run that alone needs more is refused by name.

use std::str::FromStr;
use std::sync::{Condvar, Mutex};

/// What the user asked for: the budget found from the machine, or a size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MemoryLimit {
    /// Three quarters of the memory available at start ([`available`]).
    #[default]
    Auto,
    /// This many bytes.
    Bytes(u64),
}

impl FromStr for MemoryLimit {
    type Err = String;

    /// `auto`, or a size: a number with an optional unit `K`, `M`, `G` or
    /// `T` (powers of 1024, either case), with or without a trailing `B` or
    /// `iB`: `8G`, `8g`, `512MiB`, `1.5GB`, `2000000000`.
    fn from_str(s: &str) -> Result<Self, String> {
        let t = s.trim();
        if t.eq_ignore_ascii_case("auto") {
            return Ok(MemoryLimit::Auto);
        }
        let split = t
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(t.len());
        let (number, unit) = t.split_at(split);
        let unit = unit.trim();
        let upper = unit.to_ascii_uppercase();
        let scale: f64 = match upper.trim_end_matches("IB").trim_end_matches('B') {
            "" => 1.0,
            "K" => 1024.0,
            "M" => 1024f64.powi(2),
            "G" => 1024f64.powi(3),
            "T" => 1024f64.powi(4),
            _ => {
                return Err(format!(
                    "'{s}': unknown unit '{unit}' (a size such as 8G, 512MiB or 2000000000, or auto)"
                ));
            }
        };
        let value: f64 = number.parse().map_err(|_| {
            format!("'{s}' is not a size (such as 8G, 512MiB or 2000000000, or auto)")
        })?;
        let bytes = value * scale;
        // At least 1 MiB (a budget below one run's fixed buffers admits
        // nothing useful); at most 2^60 (an exabyte: no machine has more).
        if !(bytes >= 1024.0 * 1024.0 && bytes <= 2f64.powi(60)) {
            return Err(format!(
                "'{s}': a memory limit must be between 1 MiB and 1 EiB"
            ));
        }
        Ok(MemoryLimit::Bytes(bytes as u64))
    }
}

/// The budget in force, and where it came from (for messages).
#[derive(Debug, Clone, PartialEq)]
pub struct MemoryBudget {
    /// `None`: no limit (nothing could be learnt about the machine).
    pub bytes: Option<u64>,
    pub origin: String,
}

impl MemoryBudget {
    /// The budget `limit` asks for on this machine.
    pub fn resolve(limit: MemoryLimit) -> Self {
        let budget = Self::of(limit);
        tracing::debug!(
            "memory budget: {:?} bytes ({})",
            budget.bytes,
            budget.origin
        );
        budget
    }

    fn of(limit: MemoryLimit) -> Self {
        match limit {
            MemoryLimit::Bytes(b) => MemoryBudget {
                bytes: Some(b),
                origin: "--memory-limit".into(),
            },
            MemoryLimit::Auto => match available() {
                Some((bytes, source)) => MemoryBudget {
                    bytes: Some(bytes / 4 * 3),
                    origin: format!("75 % of the {} available ({source})", human(bytes)),
                },
                None => MemoryBudget {
                    bytes: None,
                    origin: "no limit: the memory available is unknown here".into(),
                },
            },
        }
    }

    /// Why a run needing `need` bytes cannot be admitted at all, if so.
    pub(crate) fn refuses(&self, need: u64) -> Option<String> {
        let budget = self.bytes?;
        (need > budget).then(|| {
            format!(
                "the run needs about {} of memory to decode and reduce, more than the budget of \
                 {} ({}): free memory, or give a larger --memory-limit where the machine has it",
                human(need),
                human(budget),
                self.origin
            )
        })
    }
}

/// A size for people: `3.2 GiB`, `512.0 MiB`.
pub fn human(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// The memory this process may use, and what said so: the smaller of the
/// system's available memory (`MemAvailable`) and the control group's
/// limit (v2 `memory.max` of this process's group or an ancestor, v1
/// `memory.limit_in_bytes`). `None` where neither can be read (not Linux).
pub fn available() -> Option<(u64, &'static str)> {
    let mem = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| meminfo_available(&t))
        .map(|b| (b, "MemAvailable"));
    let cgroup = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|t| cgroup_limit(&t, std::path::Path::new("/sys/fs/cgroup")))
        .map(|b| (b, "the control group's memory limit"));
    match (mem, cgroup) {
        (Some(m), Some(c)) => Some(if c.0 < m.0 { c } else { m }),
        (m, c) => m.or(c),
    }
}

/// `MemAvailable` of a `/proc/meminfo` text, in bytes.
fn meminfo_available(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The smallest memory limit of this process's control group and its
/// ancestors, from `/proc/self/cgroup`'s text and the mount `root`.
/// "max" (v2) and v1's "no limit" (near 2^63) are no limit.
fn cgroup_limit(proc_self_cgroup: &str, root: &std::path::Path) -> Option<u64> {
    let read = |p: std::path::PathBuf| -> Option<u64> {
        let t = std::fs::read_to_string(p).ok()?;
        let v: u64 = t.trim().parse().ok()?;
        (v < 1 << 62).then_some(v)
    };
    let mut best: Option<u64> = None;
    for line in proc_self_cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let (base, file) = if id == "0" && controllers.is_empty() {
            (root.to_path_buf(), "memory.max")
        } else if controllers.split(',').any(|c| c == "memory") {
            (root.join("memory"), "memory.limit_in_bytes")
        } else {
            continue;
        };
        // The group's own folder and its ancestors; inside a container the
        // group's path may not exist under the mount, whose root is then
        // the group itself.
        let mut dir = std::path::PathBuf::from(path.trim_start_matches('/'));
        loop {
            if let Some(v) = read(base.join(&dir).join(file)) {
                best = Some(best.map_or(v, |b| b.min(v)));
            }
            if !dir.pop() {
                break;
            }
        }
    }
    best
}

/// Admits runs while their needs fit the budget: the caller asks before a
/// run starts and gives its need back when the run's outputs are handed
/// on. A run is always admitted when nothing else is in flight, so a need
/// above the budget (which [`MemoryBudget::refuses`] turns away first)
/// cannot stop the batch.
pub(crate) struct Admission {
    budget: Option<u64>,
    in_flight: Mutex<u64>,
    freed: Condvar,
}

impl Admission {
    pub(crate) fn new(budget: &MemoryBudget) -> Self {
        Admission {
            budget: budget.bytes,
            in_flight: Mutex::new(0),
            freed: Condvar::new(),
        }
    }

    fn fits(&self, in_flight: u64, need: u64) -> bool {
        in_flight == 0
            || self
                .budget
                .is_none_or(|b| in_flight.saturating_add(need) <= b)
    }

    /// Waits until `need` fits beside what is in flight, then counts it
    /// until the returned guard is dropped (also when a panic unwinds
    /// past it, so that a failed run cannot leave the others waiting).
    /// On a rayon worker (a caller inside a pool) the wait runs the pool's
    /// pending work instead of blocking, so that the runs in flight, which
    /// may be queued behind the caller, can finish.
    pub(crate) fn admit(&self, need: u64) -> Held<'_> {
        let mut g = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
        while !self.fits(*g, need) {
            if rayon::current_thread_index().is_some() {
                drop(g);
                if rayon::yield_now() != Some(rayon::Yield::Executed) {
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
                g = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
            } else {
                g = self.freed.wait(g).unwrap_or_else(|p| p.into_inner());
            }
        }
        *g += need;
        Held {
            admission: self,
            need,
        }
    }

    fn release(&self, need: u64) {
        let mut g = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
        *g = g.saturating_sub(need);
        self.freed.notify_all();
    }
}

/// A run's admitted need, given back when dropped.
pub(crate) struct Held<'a> {
    admission: &'a Admission,
    need: u64,
}

impl Drop for Held<'_> {
    fn drop(&mut self) {
        self.admission.release(self.need);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    #[test]
    fn sizes_are_read_in_powers_of_1024() {
        let b = |s: &str| match s.parse::<MemoryLimit>() {
            Ok(MemoryLimit::Bytes(b)) => b,
            other => panic!("{s}: {other:?}"),
        };
        assert_eq!(b("8G"), 8 << 30);
        assert_eq!(b("8GiB"), 8 << 30);
        assert_eq!(b("8 GB"), 8 << 30);
        assert_eq!(b("512M"), 512 << 20);
        assert_eq!(b("1.5G"), 3 << 29);
        assert_eq!(b("2000000000"), 2_000_000_000);
        assert_eq!(b("1T"), 1 << 40);
        assert_eq!(b("8g"), 8 << 30);
        assert_eq!(b("2048kb"), 2 << 20);
        assert_eq!("auto".parse::<MemoryLimit>(), Ok(MemoryLimit::Auto));
        for bad in [
            "", "G", "8X", "-1G", "nan", "1e3G", "0", "1023K", "2E", "1.2.3G",
        ] {
            assert!(bad.parse::<MemoryLimit>().is_err(), "{bad}");
        }
    }

    #[test]
    fn meminfo_and_cgroup_limits_are_read() {
        let text = "MemTotal:       24684084 kB\nMemFree: 1 kB\nMemAvailable:   23556556 kB\n";
        assert_eq!(meminfo_available(text), Some(23_556_556 * 1024));
        assert_eq!(meminfo_available("MemTotal: 1 kB\n"), None);

        let root = tempfile::tempdir().unwrap();
        let put = |rel: &str, v: &str| {
            let p = root.path().join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, v).unwrap();
        };
        // v2: the parent's limit is the smaller one; "max" is no limit.
        put("a/memory.max", "3000000000\n");
        put("a/b/memory.max", "max\n");
        assert_eq!(cgroup_limit("0::/a/b\n", root.path()), Some(3_000_000_000));
        // v1: the container's view (the group's path absent under the mount).
        put("memory/memory.limit_in_bytes", "2147483648\n");
        assert_eq!(
            cgroup_limit("4:memory:/docker/xyz\n", root.path()),
            Some(2_147_483_648)
        );
        put(
            "memory/docker/xyz/memory.limit_in_bytes",
            "9223372036854771712\n",
        );
        assert_eq!(
            cgroup_limit("4:memory:/docker/xyz\n", root.path()),
            Some(2_147_483_648)
        );
        assert_eq!(cgroup_limit("1:cpu:/\n", root.path()), None);
    }

    #[test]
    fn a_run_above_the_budget_is_refused_and_one_within_is_not() {
        let b = MemoryBudget::resolve(MemoryLimit::Bytes(1 << 30));
        assert_eq!(b.refuses(1 << 30), None);
        let why = b.refuses((1 << 30) + 1).unwrap();
        assert!(
            why.contains("1.0 GiB") && why.contains("--memory-limit"),
            "{why}"
        );
        let none = MemoryBudget {
            bytes: None,
            origin: String::new(),
        };
        assert_eq!(none.refuses(u64::MAX), None);
    }

    #[derive(Clone, Copy)]
    struct Jobs<'a> {
        needs: &'a [u64],
        admission: &'a Admission,
        now: &'a AtomicU64,
        peak: &'a AtomicU64,
        ran: &'a AtomicU64,
    }

    impl<'a> Jobs<'a> {
        /// Each job admitted as `extract_runs` admits a run, then spawned.
        fn spawn_all(self, s: &rayon::Scope<'a>) {
            for &need in self.needs {
                let held = self.admission.admit(need);
                s.spawn(move |_| {
                    let _held = held;
                    let held = self.now.fetch_add(need, Ordering::SeqCst) + need;
                    self.peak.fetch_max(held, Ordering::SeqCst);
                    std::thread::sleep(std::time::Duration::from_micros(200));
                    self.now.fetch_sub(need, Ordering::SeqCst);
                    self.ran.fetch_add(1, Ordering::SeqCst);
                });
            }
        }
    }

    /// Jobs of random needs on a pool of `threads`, dispatched as
    /// `extract_runs` does (from inside the pool when `inside`): every job
    /// runs, and what is in flight never passes the budget.
    fn dispatch(threads: usize, inside: bool) {
        use rand::{Rng, SeedableRng};
        let budget = MemoryBudget::resolve(MemoryLimit::Bytes(100 << 20));
        let admission = Admission::new(&budget);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(threads as u64);
        let needs: Vec<u64> = (0..60)
            .map(|_| rng.random_range(1..=100u64) << 20)
            .collect();
        let (now, peak, ran) = (AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0));
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let jobs = Jobs {
            needs: &needs,
            admission: &admission,
            now: &now,
            peak: &peak,
            ran: &ran,
        };
        if inside {
            pool.install(|| rayon::in_place_scope(|s| jobs.spawn_all(s)));
        } else {
            pool.in_place_scope(|s| jobs.spawn_all(s));
        }
        assert_eq!(ran.load(Ordering::SeqCst), needs.len() as u64);
        assert!(peak.load(Ordering::SeqCst) <= 100 << 20);
    }

    /// A job that panics gives its need back as it unwinds: the jobs
    /// after it, each needing the whole budget, are still admitted, and
    /// the panic reaches the caller instead of the dispatch waiting on.
    #[test]
    fn a_panicking_run_gives_its_need_back() {
        let budget = MemoryBudget::resolve(MemoryLimit::Bytes(8 << 20));
        let admission = Admission::new(&budget);
        let ran = AtomicU64::new(0);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.in_place_scope(|s| {
                for k in 0..6 {
                    let held = admission.admit(8 << 20);
                    let ran = &ran;
                    s.spawn(move |_| {
                        let _held = held;
                        assert_ne!(k, 1, "run {k} fails");
                        ran.fetch_add(1, Ordering::SeqCst);
                    });
                }
            })
        }));
        assert!(caught.is_err());
        assert_eq!(ran.load(Ordering::SeqCst), 5);
    }

    #[test]
    fn admitted_runs_never_exceed_the_budget_and_all_run() {
        for threads in [1, 2, 4] {
            dispatch(threads, true);
            dispatch(threads, false);
        }
    }
}
