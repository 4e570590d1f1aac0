//! Storage, knowing no physics: Parquet files written atomically with the campaign's identity
//! in their footer ([`parquet_io`]), a campaign's tables as generation directories
//! ([`layout`], [`dataset`]), Arrow column builders and readers ([`cols`]), checkpoint files
//! ([`checkpoint`]).

pub mod checkpoint;
pub mod cols;
pub mod dataset;
pub mod layout;
pub mod parquet_io;

/// Version of the on-disk layout (tables, ledger, checkpoints); written everywhere.
pub const FORMAT_VERSION: u32 = 1;
