//! Sim-to-real gap diagnosis (issue 6), in progress: the physics baseline,
//! step 1 (where the gap lies, slices with false-discovery control), and
//! first versions of step 2 (candidate effects by grouped cross-validation)
//! and step 3 (forward selection); `gap validate` follows. Definitions and
//! what works so far: docs/gap.md.

pub mod baseline;
pub mod candidates;
pub mod report;
pub mod slices;
pub mod stats;
