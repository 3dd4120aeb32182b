//! Sim-to-real gap diagnosis (issue 6), started: the physics baseline and
//! step 1, where the gap lies (slices with false-discovery control). Steps 2
//! (which unmodelled effect) and 3 (how far the gap shrinks), and
//! `gap validate`, follow. Definitions: docs/gap.md.

pub mod baseline;
pub mod report;
pub mod slices;
pub mod stats;
