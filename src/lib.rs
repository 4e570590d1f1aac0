//! `granular`: ensembles of granular-gas simulations turned into Parquet tables.
//!
//! Layers (see `ARCHITECTURE.md`):
//! - [`manifest`]: the JSON manifest as serde types, its JSON Schema, and validation that
//!   reports every error at once with its JSON path.
//! - [`plan`]: expands a manifest's sweep into points and runs with stable ids and seeds.
//! - [`dsmc`]: the DSMC simulators (low-rank and Bird) of polydisperse granular gases.
//! - [`aux_models`]: the thesis's auxiliary models (bisection, cascade, single particle).
//! - [`theory`]: kinetic theory (pure functions, usable without simulating).
//! - [`store`]: Parquet tables, atomic part files, checkpoints.
//! - [`campaign`]: the engine: worker pool, dispatcher, ledger, locks, resume, status.
//! - [`engine`]: the closed set of simulators the campaign drives.
//!
//! The physics never imports the campaign or the store: a simulator hands rows and
//! checkpoint bytes to whoever drives it.

pub mod analysis;
pub mod aux_models;
pub mod campaign;
pub mod cli;
pub mod dsmc;
pub mod exit_codes;
pub mod fsutil;
pub mod manifest;
pub mod math;
pub mod memory;
pub mod models;
pub mod physics;
pub mod plot;
pub mod rfm;
pub mod rng;
pub mod store;
pub mod theory;

/// The code version written into every table and checkpoint.
pub const CODE_VERSION: &str = concat!("granular ", env!("CARGO_PKG_VERSION"));
