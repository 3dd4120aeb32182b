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

pub use extract::{Engine, ExtractOptions, ExtractSummary, extract, run_memory_need};
pub use table::KpiRow;

/// A tire in a run, (run, wheel): the key of every per-tire table (KPI
/// rows, energy and condition maps, predictions, truth).
pub(crate) type TireRun = (String, crate::Wheel);

/// Parses a side table's wheel cell, naming the file and record when it is
/// not a wheel position.
pub(crate) fn wheel_cell(
    path: &std::path::Path,
    record: usize,
    text: &str,
) -> Result<crate::Wheel, crate::ingest::IngestError> {
    text.parse().map_err(|_| {
        crate::ingest::IngestError::invalid(
            path,
            format!("record {record}"),
            format!("wheel '{text}' is not FL, FR, RL or RR"),
        )
    })
}
