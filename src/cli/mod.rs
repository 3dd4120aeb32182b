//! The subcommands, one module each: its arguments (clap) and what it
//! runs. The library (`tirewear`) knows nothing of the command line; `main`
//! only parses and maps the outcome to an exit code.

pub(crate) mod allocator;
pub(crate) mod bench;
pub(crate) mod demo;
pub(crate) mod device_select;
pub(crate) mod extract;
pub(crate) mod fit;
pub(crate) mod gap;
pub(crate) mod import;
pub(crate) mod predict;
pub(crate) mod process;
pub(crate) mod report;
pub(crate) mod simulate;
