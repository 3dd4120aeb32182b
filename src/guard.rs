//! A panic met by one input's data becomes that input's error, so that one
//! run, log or season cannot end a batch (docs/reliability.md). Every input
//! is checked before use and no panic is known; this is the net under
//! those checks.

use std::panic::{AssertUnwindSafe, catch_unwind};

/// Runs `f`; a panic comes back as `Err` with its message. The caller
/// discards whatever `f` was changing (a run's buffers, a manifest's copy),
/// so unwinding through `f` leaves nothing half-done behind.
pub(crate) fn catch_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into())
    })
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
}
