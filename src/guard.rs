//! A panic met by one input's data becomes that input's error, so that one
//! run, log or season cannot end a batch (docs/reliability.md). Every input
//! is checked before use and no panic is known; this is the net under
//! those checks.

use std::cell::{Cell, RefCell};
use std::panic::{AssertUnwindSafe, catch_unwind};

thread_local! {
    /// How many [`catch_panic`] calls this thread is inside.
    static CATCHING: Cell<usize> = const { Cell::new(0) };
    /// Where the panic being caught on this thread happened, when the hook
    /// of [`quiet_caught_panics`] is installed.
    static PLACE: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Runs `f`; a panic comes back as `Err` with its message (and, under the
/// hook of [`quiet_caught_panics`], the place it happened). The caller
/// discards whatever `f` was changing (a run's buffers, a manifest's copy),
/// so unwinding through `f` leaves nothing half-done behind.
pub(crate) fn catch_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    CATCHING.with(|c| c.set(c.get() + 1));
    let caught = catch_unwind(AssertUnwindSafe(f));
    CATCHING.with(|c| c.set(c.get() - 1));
    caught.map_err(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        match PLACE.with(|at| at.borrow_mut().take()) {
            Some(at) => format!("{msg}, at {at}"),
            None => msg,
        }
    })
}

/// Installs a panic hook for the command line: a panic that [`catch_panic`]
/// will catch is not printed as a crash (it becomes the error of the input
/// it was met in, which says so with the message and place, and is logged
/// at debug level); every other panic goes to the hook installed before
/// (Rust's default: the message, and a backtrace under `RUST_BACKTRACE`).
/// A panic on another thread (a rayon worker inside a caught closure)
/// still goes to the previous hook.
pub fn quiet_caught_panics() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if CATCHING.with(Cell::get) == 0 {
            return previous(info);
        }
        let at = info
            .location()
            .map(|l| format!("{}:{}:{}", short_path(l.file()), l.line(), l.column()));
        tracing::debug!(
            place = at.as_deref(),
            "caught panic: {}",
            info.payload_as_str().unwrap_or("unknown panic")
        );
        PLACE.with(|p| *p.borrow_mut() = at);
    }));
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
}
