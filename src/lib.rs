//! `granular`: ensembles of granular-gas simulations turned into Parquet tables.
//!
//! Layers (see `ARCHITECTURE.md`; `tests/it/architecture.rs` checks the arrows):
//! - [`cli`]: the command line, one file per command; the only layer that prints.
//! - [`campaign`]: the engine, the same for every model: plan, worker pool, dispatcher,
//!   writer, ledger, locks, resume, status, SLURM, compaction, verification.
//! - [`manifest`]: the JSON manifest's envelope, its JSON Schema, stages 1-2 of validation.
//! - [`models`]: one home per model (params, tables, summaries, theory, figures) behind the
//!   `Model` trait, and the closed list of models.
//! - the simulators [`dsmc`], [`rfm`], [`aux_models`] (with [`physics`], [`rng`]): they know
//!   no manifest, table or campaign; a simulator hands rows and checkpoint bytes to whoever
//!   drives it.
//! - [`theory`]: kinetic theory (pure functions, usable without simulating), on [`math`].
//! - [`store`]: Parquet tables, datasets, atomic files, checkpoints; knows no physics.
//! - [`analysis`]: what every model's analysis (`granular analyze`, in the model's home)
//!   shares; [`plot`]: the figure renderer.
//! - [`report`]: one HTML page of a campaign; [`serve`]: that page live over HTTP, with the
//!   status JSON and the table files (read-only).

pub mod analysis;
pub mod aux_models;
pub mod campaign;
pub mod cli;
pub mod derived;
pub mod dsmc;
pub mod exit_codes;
pub mod fsutil;
pub mod manifest;
pub mod math;
pub mod memory;
pub mod models;
pub mod physics;
pub mod plot;
pub mod report;
pub mod rfm;
pub mod rng;
pub mod serve;
pub mod store;
pub mod theory;

/// The code version written into every table and checkpoint.
pub const CODE_VERSION: &str = concat!("granular ", env!("CARGO_PKG_VERSION"));
