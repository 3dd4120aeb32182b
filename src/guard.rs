//! A panic met by one input's data becomes that input's error, so that one
//! run, log or season cannot end a batch (docs/reliability.md). Every input
//! is checked before use and no panic is known; this is the net under
//! those checks.

use std::cell::Cell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::thread::ThreadId;

/// How many [`catch_panic`] calls are in progress, on all threads.
static CATCHING_ANYWHERE: AtomicUsize = AtomicUsize::new(0);

/// Panics that [`quiet_caught_panics`]'s hook held back, to be claimed by
/// the catch they reach (its error then gives their place) or, if none
/// does, printed by [`print_held_panics`] as Rust would have printed them.
/// At most [`HELD_MAX`] are kept.
static HELD: Mutex<Vec<HeldPanic>> = Mutex::new(Vec::new());
const HELD_MAX: usize = 16;

/// One held panic: what Rust's hook would have printed.
struct HeldPanic {
    thread: ThreadId,
    thread_name: String,
    message: String,
    place: Option<String>,
    backtrace: std::backtrace::Backtrace,
}

thread_local! {
    /// How many [`catch_panic`] calls this thread is inside.
    static CATCHING: Cell<usize> = const { Cell::new(0) };
}

/// Runs `f`; a panic comes back as `Err` with its message (and, under the
/// hook of [`quiet_caught_panics`], the place it happened). The caller
/// discards whatever `f` was changing (a run's buffers, a manifest's copy),
/// so unwinding through `f` leaves nothing half-done behind.
pub(crate) fn catch_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    CATCHING.with(|c| c.set(c.get() + 1));
    CATCHING_ANYWHERE.fetch_add(1, Ordering::SeqCst);
    let caught = catch_unwind(AssertUnwindSafe(f));
    CATCHING_ANYWHERE.fetch_sub(1, Ordering::SeqCst);
    CATCHING.with(|c| c.set(c.get() - 1));
    caught.map_err(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        match claim_held(&msg) {
            Some(at) => format!("{msg}, at {at}"),
            None => msg,
        }
    })
}

/// The place of the held panic with `message`, taken off the held list:
/// the newest on this thread, else the newest on another (a rayon worker,
/// from which rayon carried it here).
fn claim_held(message: &str) -> Option<String> {
    let mut held = HELD.lock().unwrap_or_else(|p| p.into_inner());
    let here = std::thread::current().id();
    let newest = |on_here: bool| {
        held.iter()
            .rposition(|h| h.message == message && (h.thread == here) == on_here)
    };
    let i = newest(true).or_else(|| newest(false))?;
    held.remove(i).place
}

/// Installs a panic hook for the command line: a panic that [`catch_panic`]
/// will catch is not printed as a crash (it becomes the error of the input
/// it was met in, which says so with the message and place, and is logged
/// at debug level); every other panic goes to the hook installed before
/// (Rust's default: the message, and a backtrace under `RUST_BACKTRACE`).
///
/// Which catch a panic reaches is known only when it gets there: rayon
/// carries a panic on a worker to the thread that started the parallel
/// work (parallel work inside a caught closure runs on the workers, and a
/// worker waiting inside a catch may run another thread's work). So a
/// panic inside a catch, or on a rayon worker while a catch is in progress
/// anywhere, is held; the catch it reaches claims it, and one that no
/// catch claims is printed by [`print_held_panics`], which the command
/// line calls when a panic ends it.
pub fn quiet_caught_panics() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let inside = CATCHING.with(Cell::get) > 0;
        let on_worker =
            rayon::current_thread_index().is_some() && CATCHING_ANYWHERE.load(Ordering::SeqCst) > 0;
        if !inside && !on_worker {
            return previous(info);
        }
        let message = info.payload_as_str().unwrap_or("unknown panic");
        let place = info
            .location()
            .map(|l| format!("{}:{}:{}", short_path(l.file()), l.line(), l.column()));
        tracing::debug!(place = place.as_deref(), "held panic: {message}");
        let thread = std::thread::current();
        hold(HeldPanic {
            thread: thread.id(),
            thread_name: thread.name().unwrap_or("<unnamed>").into(),
            message: message.into(),
            place,
            backtrace: std::backtrace::Backtrace::capture(),
        });
    }));
}

/// Adds `panic` to the held list; past [`HELD_MAX`] the oldest is printed
/// (rayon keeps one panic of a parallel call and drops the others, which no
/// catch then claims).
fn hold(panic: HeldPanic) {
    let mut held = HELD.lock().unwrap_or_else(|p| p.into_inner());
    if held.len() == HELD_MAX {
        eprint!("{}", held.remove(0));
    }
    held.push(panic);
}

/// Prints, as Rust's hook would have, the held panics no catch claimed
/// (see [`quiet_caught_panics`]); for a command ended by a panic, before it
/// exits.
pub fn print_held_panics() {
    let held = std::mem::take(&mut *HELD.lock().unwrap_or_else(|p| p.into_inner()));
    for panic in held {
        eprint!("{panic}");
    }
}

impl std::fmt::Display for HeldPanic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let at = self.place.as_deref().unwrap_or("an unknown place");
        writeln!(
            f,
            "thread '{}' panicked at {at}:\n{}",
            self.thread_name, self.message
        )?;
        if self.backtrace.status() == std::backtrace::BacktraceStatus::Captured {
            writeln!(f, "stack backtrace:\n{}", self.backtrace)?;
        }
        Ok(())
    }
}

/// A source path without the cargo registry's folders: a dependency's file
/// as `parquet-60.1.0/src/util/bit_util.rs`.
fn short_path(file: &str) -> &str {
    match file.rsplit_once("/registry/src/") {
        // After the index's folder (`index.crates.io-…/`).
        Some((_, rest)) => rest.split_once('/').map_or(rest, |(_, path)| path),
        None => file,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_is_an_error_with_its_message() {
        assert_eq!(catch_panic(|| 7), Ok(7));
        let v: Vec<u8> = Vec::new();
        let e = catch_panic(|| v[3]).unwrap_err();
        assert!(e.contains("index out of bounds"), "{e}");
        let e = catch_panic(|| panic!("run {} is odd", 4)).unwrap_err();
        assert_eq!(e, "run 4 is odd");
    }

    #[test]
    fn a_dependencys_place_is_shown_from_its_crate_folder() {
        let file = "/root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/parquet-60.1.0/src/util/bit_util.rs";
        assert_eq!(short_path(file), "parquet-60.1.0/src/util/bit_util.rs");
        assert_eq!(short_path("src/kpi/table.rs"), "src/kpi/table.rs");
    }

    /// The panic hook is the process's, so its test runs in a child
    /// process: this test binary again, running only [`hook_child`], whose
    /// output is checked against what Rust's own hook prints.
    #[test]
    fn a_panic_on_a_rayon_worker_in_a_catch_is_its_error_and_an_uncaught_one_is_printed() {
        let child = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "guard::tests::hook_child",
                "--exact",
                "--ignored",
                "--nocapture",
            ])
            .args(["--test-threads", "1"])
            .env(HOOK_CHILD, "1")
            .env_remove("RUST_BACKTRACE")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&child.stdout);
        let stderr = String::from_utf8_lossy(&child.stderr);
        assert!(child.status.success(), "{stdout}\n{stderr}");
        assert!(stdout.contains("1 passed"), "{stdout}");
        let said = |key: &str| {
            // (libtest's "test … ... " begins the first line.)
            let line = stdout
                .lines()
                .find_map(|l| l.split_once(key).map(|(_, v)| v));
            line.unwrap_or_else(|| panic!("no {key} in {stdout}"))
                .to_string()
        };
        // Caught: the catch's error has the worker's place; nothing printed.
        let line = said("caught line ");
        let caught = said("caught: ");
        let place = format!("cell 37 is odd, at src/guard.rs:{line}:");
        assert!(caught.starts_with(&place), "{caught}");
        let line = said("worker line ");
        let caught = said("on a worker: ");
        let place = format!("tire 2 is odd, at src/guard.rs:{line}:");
        assert!(caught.starts_with(&place), "{caught}");
        assert!(
            !stderr.contains("cell 37") && !stderr.contains("tire 2"),
            "{stderr}"
        );
        // Not caught while a catch ran elsewhere: held, then printed as
        // Rust prints a panic (the line of the `panic!` below).
        let line = said("held line ");
        assert!(printed(&stderr, &line, "row 5 is odd"), "{stderr}");
        assert_eq!(stderr.matches("row 5 is odd").count(), 1, "{stderr}");
        // No catch anywhere: Rust's hook prints it when it happens.
        let line = said("free line ");
        assert!(printed(&stderr, &line, "lap 9 is odd"), "{stderr}");
    }

    /// Whether `stderr` says, as Rust's hook does, that a thread panicked
    /// at this file's `line` (any column) with `message`.
    fn printed(stderr: &str, line: &str, message: &str) -> bool {
        let at = format!("panicked at src/guard.rs:{line}:");
        stderr.match_indices(&at).any(|(i, _)| {
            let rest = &stderr[i + at.len()..];
            let column = rest.chars().take_while(char::is_ascii_digit).count();
            column > 0 && rest[column..].starts_with(&format!(":\n{message}\n"))
        })
    }

    const HOOK_CHILD: &str = "TIREWEAR_GUARD_HOOK_CHILD";

    /// Run by the test above in a child process (does nothing otherwise).
    #[test]
    #[ignore = "run in a child process by a_panic_on_a_rayon_worker_in_a_catch_…"]
    fn hook_child() {
        if std::env::var_os(HOOK_CHILD).is_none() {
            return;
        }
        quiet_caught_panics();
        // Parallel work started outside the pool runs on its workers.
        let e = catch_panic(|| panic_in_parallel("caught", "cell", 37));
        println!("caught: {}", e.unwrap_err());
        // A catch on a worker (a run prepared in a rayon task).
        rayon::scope(|s| {
            s.spawn(|_| {
                let e = catch_panic(|| {
                    println!("worker line {}", line!() + 1);
                    panic!("tire {} is odd", 2)
                });
                println!("on a worker: {}", e.unwrap_err());
            })
        });

        // A catch in progress on another thread while this one's parallel
        // work panics with nothing to catch it but `main`'s.
        let (started, wait) = (std::sync::Barrier::new(2), std::sync::Barrier::new(2));
        std::thread::scope(|s| {
            s.spawn(|| {
                catch_panic(|| {
                    started.wait();
                    wait.wait();
                })
            });
            started.wait();
            let ended = catch_unwind(|| panic_in_parallel("held", "row", 5));
            assert!(ended.is_err());
            print_held_panics();
            wait.wait();
        });

        let ended = catch_unwind(|| panic_in_parallel("free", "lap", 9));
        assert!(ended.is_err());
    }

    /// A parallel loop of 64 items (on rayon's workers) whose item `at`
    /// panics with "`what` `at` is odd", having printed "`key` line N", N the
    /// `panic!`'s line.
    fn panic_in_parallel(key: &str, what: &str, at: usize) {
        use rayon::prelude::*;
        (0..64).into_par_iter().for_each(|i| {
            if i == at {
                println!("{key} line {}", line!() + 1);
                panic!("{what} {i} is odd");
            }
        })
    }
}
