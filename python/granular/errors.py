"""The exceptions of the Python API: each carries what the `granular` binary said."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence


class GranularError(Exception):
    """A `granular` command refused or failed.

    `exit_code` is the binary's exit code (see the README's "Exit codes"), `message` what it
    printed on standard error (or the API's own explanation), `command` the argument list run.
    """

    def __init__(
        self,
        message: str,
        *,
        exit_code: Optional[int] = None,
        command: Optional[Sequence[str]] = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.exit_code = exit_code
        self.command = list(command) if command is not None else None


@dataclass(frozen=True)
class Problem:
    """One error of a manifest: its JSON pointer (`/params/restitution`; `/` for the whole
    manifest) and what is wrong there."""

    path: str
    message: str

    def __str__(self) -> str:
        return f"at {self.path}: {self.message}"


class ManifestError(GranularError, ValueError):
    """The manifest is invalid: `errors` holds every problem found, each with its JSON path.
    Nothing was written."""

    def __init__(self, file: str, errors: Sequence[Problem], *, exit_code: int = 2) -> None:
        n = len(errors)
        lines = [f"{file}: invalid manifest ({n} error{'' if n == 1 else 's'})"]
        lines += [f"  {e}" for e in errors]
        super().__init__("\n".join(lines), exit_code=exit_code)
        self.file = file
        self.errors = list(errors)


class CampaignError(GranularError):
    """The campaign directory was refused: not a campaign, another campaign, locked by a live
    process, of a format this granular does not know, or damaged (see `CampaignDamaged`)."""


class CampaignDamaged(CampaignError):
    """The campaign's tables do not match its ledger (the quick check failed). No rows are
    returned from a damaged campaign; `granular resume DIR` (or `Campaign.resume()`) heals it."""


class TableNotWritten(GranularError, LookupError):
    """The table exists in this campaign but is not written yet (summaries are written once
    every run the manifest asks for has finished)."""


class RunsFailed(GranularError):
    """The campaign finished but some runs failed (NaN, runaway overlap, ...): their reasons
    are in the `runs` table (`status = 'failed'`). `campaign` is the campaign, readable."""

    def __init__(self, message: str, campaign, *, exit_code: int = 1, command=None) -> None:
        super().__init__(message, exit_code=exit_code, command=command)
        self.campaign = campaign


class Interrupted(GranularError):
    """The run was stopped (Ctrl-C, SIGTERM, the kernel interrupted) after checkpointing;
    `Campaign.resume()` or `granular resume DIR` continues it bit-identically."""

    def __init__(self, message: str, campaign, *, exit_code: int = 130, command=None) -> None:
        super().__init__(message, exit_code=exit_code, command=command)
        self.campaign = campaign
