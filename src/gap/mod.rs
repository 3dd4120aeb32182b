//! Sim-to-real gap diagnosis: the physics baseline, step 1 (where the gap
//! lies: slices with false-discovery control), step 2 (which unmodelled
//! effect: candidate mechanisms scored by grouped cross-validation and a
//! permutation test), step 3 (forward selection: how far the gap shrinks),
//! then the findings in words. Its validation on simulated seasons lives
//! apart, in `crate::validate`. Definitions and measured results: docs/gap.md.

pub mod acts;
pub mod baseline;
pub mod candidates;
pub mod error;
pub mod linear;
pub mod recalibrate;
pub mod render;
pub mod report;
pub mod scoring;
pub mod selection;
pub mod slices;
pub mod stats;
pub mod track_test;
pub mod user_effects;
