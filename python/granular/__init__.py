"""granular from Python: run campaigns of granular-gas simulations and read their tables as
Polars LazyFrames, pyarrow datasets and DuckDB views, with the swept parameters joined.

    import granular
    c = granular.run("jobs/table1-small.json", out="runs/p")   # or granular.open("runs/p")
    c.table("dsmc_species_summary").collect()                   # a Polars DataFrame
    c.duckdb().sql("select * from dsmc_species where method = 'bird'")

The `granular` binary installed with this package does the work; this module runs it (never
through a shell) and reads the Parquet tables it writes.
"""

from __future__ import annotations

from importlib import metadata as _metadata

from ._api import open, run, validate
from ._binary import binary
from .campaign import Campaign
from .errors import (
    CampaignDamaged,
    CampaignError,
    GranularError,
    Interrupted,
    ManifestError,
    Problem,
    RunsFailed,
    TableNotWritten,
)

try:
    __version__ = _metadata.version("granular")
except _metadata.PackageNotFoundError:  # a source checkout on PYTHONPATH
    __version__ = "0.0.0+unknown"

__all__ = [
    "Campaign",
    "CampaignDamaged",
    "CampaignError",
    "GranularError",
    "Interrupted",
    "ManifestError",
    "Problem",
    "RunsFailed",
    "TableNotWritten",
    "binary",
    "open",
    "run",
    "validate",
]
