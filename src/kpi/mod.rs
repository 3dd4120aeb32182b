//! KPI extraction (paper section 3): every tire and run becomes one row of
//! road (table 3), telemetry (table 4) and viscoelastic (table 5) indices
//! plus the mean wear. Formulas and units: docs/kpis.md.

pub mod cpu;
pub mod energy_maps;
pub mod extract;
pub mod road;
pub mod roughness_batch;
pub mod table;
pub mod telemetry;
pub mod viscoelastic;
pub mod wear;

pub use extract::{Engine, ExtractOptions, ExtractSummary, extract};
pub use table::KpiRow;
