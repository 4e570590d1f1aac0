//! Storage: Parquet tables written as atomic part files, checkpoints, ensemble summaries.
//! The store knows table schemas, not physics.

pub mod aux_summary;
pub mod aux_tables;
pub mod checkpoint;
pub mod layout;
pub mod parquet_io;
pub mod rfm_summary;
pub mod summary;
pub mod tables;

/// Version of the on-disk layout (tables, ledger, checkpoints); written everywhere.
pub const FORMAT_VERSION: u32 = 1;
