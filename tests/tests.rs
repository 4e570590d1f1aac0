//! Integration tests of `granular`, in one test binary (one link, shared helpers).
//!
//! - `architecture`: the import graph of `src/` has no circles and no forbidden arrows.
//! - `models`: every registered model restores bitwise from a checkpoint at a random point and
//!   runs a campaign whose tables the generic reader reads.
//! - `cli_flags`: every numeric flag of every command refused (exit 2, flag named, nothing
//!   written) for NaN, inf, negative and absurd values; valid values accepted.
//! - `manifests`: data-driven validation of `tests/manifests/{good,bad}/*.json`.
//! - `resume`: kill -9 / resume, thread count and sharding give bit-identical tables;
//!   directory refusal, re-running a finished campaign, `status --json`.
//! - `physics`: Haff's law, bitwise checkpoint/restore, conservation laws, low-rank vs Bird.
//! - `growth`: campaigns grown by replicas, sweep values, a new sweep key, given seeds and a
//!   longer t_end equal the campaign of their final manifest; refused growth changes nothing;
//!   kill -9 during growth; a format-1 campaign (committed fixture) upgraded and continued.
//! - `interrupt`: Ctrl-C once checkpoints and stops (exit 130), resume is bit-identical;
//!   twice exits at once.
//! - `rfm`: a Random Force Model campaign, its tables, kill + resume bit-identity.
//! - `analyze`: `granular analyze` end to end on tiny 1D/2D RFM campaigns; refusals.
//! - `schema`: the committed JSON Schema matches the code; `jobs/*.json` validate.
//! - `drills`: a second process on a running shard, corrupted checkpoints, truncated and
//!   foreign Parquet parts, a full disk, compaction in the middle of a campaign.
//! - `damage`: each damage to a campaign directory (flipped bytes, deleted parts, tables,
//!   records, ledger; corrupt records; foreign and orphan files) named by `verify`, refused by
//!   `compact`, healed by `resume` to identical tables; stale locks of reused pids; compaction
//!   killed at any moment.
//! - `machine`: what the Python module reads instead of text: `validate --json`; `tables
//!   --json` (every table named and described, its files, rows and columns; damage refused;
//!   a table link out of the campaign not followed); `run`/`resume --progress-json` (JSON
//!   lines on stderr, finished never decreasing, the last complete).
//! - `links`: the campaign directory is a closed world: a symbolic link where granular keeps
//!   its own file or directory (`tables`, a table, a part, `quarantine`, a ledger shard,
//!   `checkpoints`, `campaign.json`) is named by `verify`, refused by the readers, never
//!   followed (the outside directory hashed unchanged), set aside itself by `resume`.
//! - `slurm`: `granular submit --slurm` with stand-in sbatch/squeue/scontrol.
//! - `report`: `granular report` on a finished and a half-finished campaign: one HTML file,
//!   an inline SVG per figure, progress per point, no network references, escaped strings.
//! - `serve`: `granular serve` read-only: the live dashboard, `/api/status` = `status --json`,
//!   table downloads byte for byte, 405 for every other method, traversal and symlinks out
//!   refused, a running campaign followed.
//! - `sweep_columns`: every summary table of DSMC, RFM and cascade campaigns carries its
//!   point's sweep columns after `point_id`, as in `points`.
//! - `derived`: derived quantities (manifest `derived`): bad expressions refused with their
//!   paths; the `derived` and `derived_summary` tables of DSMC and RFM campaigns against values
//!   computed from the run tables; the same with one thread; their figures.
//! - `plan_cost`: `plan`'s cost estimate (core-hours, wall time at `--threads`) and the
//!   calibration it names (reference, probe, finished runs); a target campaign's pilot; the
//!   report's estimate against what the runs took.
//! - `docs`: every relative link and `#anchor` in README.md and docs/*.md resolves (GitHub's
//!   anchor rules); every property of the manifest's JSON Schema is named in docs/manifest.md;
//!   the tutorial's manifest is its job and validates as shown (the rest of docs/tutorial.md:
//!   scripts/tutorial_test.py).
//! - `labels`: the manifest's `labels` name the figures of `plot` and `report`, change no run
//!   (0 new runs), and a key naming nothing of the manifest is refused at `/labels/KEY`.
//! - `figures`: the standard figures of tiny rfm, bisection, cascade and SPM campaigns, the
//!   same in `plot` and `report`; analyze's outputs in the report; overlays split beyond 12
//!   points.
//! - `aux_models`: bisection, cascade and SPM against exact theory and the thesis's values;
//!   kill + resume bit-identity of their tables.
//! - `races`: two commands at once (racing growths, a stale resume, a growth refused while
//!   another holds the lock, `upgrade` while a shard runs), summaries of the latest manifest
//!   (fewer replicas, switched to seeds), a commit record lost during a run.
//! - `vdist`: the DSMC observable `velocity_distribution` swept on and off: `a2` where
//!   observed (null elsewhere), the speed histograms and their summary with sweep columns.
//! - `targets`: error targets: a campaign that adds replicas in rounds until every target is
//!   met decides the same replicas and writes the same tables with 1 or 2 threads, 2 shards and
//!   kill -9 + resume, and equals a direct campaign of the replicas decided.
//! - `targets_report`: the report of a target campaign has its `sec-targets` section (verdict,
//!   rounds, per point n / asked / expected and met) and the figure `targets-error`, which
//!   `granular plot` draws the same each time; a campaign without targets has neither.
//! - `streams`: random stream versions: campaigns made before they were recorded (committed
//!   fixture) resume and grow on stream 1 to the old binary's tables; a new campaign records
//!   the current version and keeps it; an unknown version is refused (exit 3).
//!
//! Heavy tests (simulations, campaigns) take `util::heavy()` so that they run one at a time:
//! the machine has few cores, and the kill test scales its kill moments to a measured run time.

mod it {
    pub mod analyze;
    pub mod architecture;
    pub mod aux_models;
    pub mod cli_flags;
    pub mod damage;
    pub mod derived;
    pub mod docs;
    pub mod drills;
    pub mod figure_quality;
    pub mod figures;
    pub mod growth;
    pub mod interrupt;
    pub mod labels;
    pub mod links;
    pub mod machine;
    pub mod manifests;
    pub mod messages;
    pub mod models;
    pub mod physics;
    pub mod plan_cost;
    pub mod races;
    pub mod report;
    pub mod resume;
    pub mod rfm;
    pub mod schema;
    pub mod serve;
    pub mod slurm;
    pub mod streams;
    pub mod sweep_columns;
    pub mod targets;
    pub mod targets_report;
    pub mod util;
    pub mod vdist;
}
