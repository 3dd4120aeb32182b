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

pub use wheel::{Axle, Wheel};
