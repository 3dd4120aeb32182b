//! tirewear: motorsport tire-wear analytics.
//!
//! Modules follow the data's path: [`ingest`] reads (and the simulator
//! writes) the season archive formats, [`sim`] simulates whole seasons with
//! known physics and planted effects. See `docs/` for formats and physics.

pub mod atomic;
pub mod bench;
mod calendar;
pub mod engine;
pub mod gap;
pub mod gpu;
mod guard;
pub mod import;
pub mod ingest;
pub mod kpi;
pub mod memory;
pub mod model;
pub mod nightly;
mod progress;
pub mod report;
pub mod sim;
pub mod validate;
pub mod wheel;

pub use guard::{print_held_panics, quiet_caught_panics};
pub use wheel::{Axle, Wheel};

/// Makes a FIFO at `path` for tests of files that must not be opened (a
/// FIFO's open waits for a writer).
#[cfg(all(test, unix))]
pub(crate) fn make_fifo(path: &std::path::Path) {
    let made = std::process::Command::new("mkfifo").arg(path).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", path.display());
}
