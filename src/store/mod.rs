//! Storage, knowing no physics: Parquet files written atomically with the campaign's identity
//! in their footer ([`parquet_io`]), a campaign's tables as generation directories
//! ([`layout`], [`dataset`]) of one schema each ([`schema`]), Arrow column builders and
//! readers ([`cols`]), typed tables declared once ([`typed`], `declare_table!`), checkpoint files ([`checkpoint`]).

pub mod checkpoint;
pub mod checksum;
pub mod cols;
pub mod dataset;
pub mod layout;
pub mod parquet_io;
pub mod schema;
pub mod typed;

/// Version of a campaign directory's layout (`campaign.json` and the tables). 2: the registry
/// of points and runs in `campaign.json` (campaigns grow), `runs` without the sweep columns
/// (they are in `points`), table files stamped with the campaign's identity. A directory of an
/// earlier version is upgraded in place by `granular upgrade` (`campaign::upgrade`). 3: the
/// ledger records every committed file's size and SHA-256 (ledger format 2), parts name
/// their commit in their footer, tables written whole have a checksum sidecar.
pub const FORMAT_VERSION: u32 = 3;

/// Version of the ledger's commit records, index and compaction journal. 2: files with sizes
/// and SHA-256; the index holds groups (commits) with their files.
pub const LEDGER_FORMAT: u32 = 2;

/// Version of SLURM submission records.
pub const SUBMISSION_FORMAT: u32 = 1;

/// Version of the checkpoint file format (the payload's layout is the model's `STATE_FORMAT`).
pub const CHECKPOINT_FORMAT: u32 = 1;
