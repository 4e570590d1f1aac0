"""Finding and running the `granular` binary installed beside this package.

Every command is run from an argument list, never through a shell: paths and manifest names
are data, never shell text.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

from .errors import CampaignDamaged, CampaignError, GranularError

EXE = "granular.exe" if os.name == "nt" else "granular"


def _candidates() -> List[Path]:
    out = []
    env = os.environ.get("GRANULAR_BIN")
    if env:
        return [Path(env)]
    # The wheel installs the binary into the scripts directory of the environment that
    # installed this package (a venv's bin/, or the user scheme's with `pip install --user`).
    for scheme in (None, f"{os.name}_user", "posix_user"):
        try:
            p = sysconfig.get_path("scripts", scheme) if scheme else sysconfig.get_path("scripts")
        except KeyError:
            continue
        if p:
            out.append(Path(p) / EXE)
    out.append(Path(sys.executable).parent / EXE)
    found = shutil.which(EXE)
    if found:
        out.append(Path(found))
    return out


def binary() -> str:
    """The path of the `granular` binary this package runs: `$GRANULAR_BIN` when set, else the
    one the wheel installed beside the Python interpreter, else the first on PATH."""
    for c in _candidates():
        if c.is_file() and os.access(c, os.X_OK):
            return str(c)
    where = ", ".join(str(c) for c in _candidates())
    raise GranularError(
        f"the granular binary was not found (looked at {where}); reinstall the package "
        "(`pip install granular`, or `pip install .` in a checkout), or set GRANULAR_BIN to "
        "the binary's path"
    )


def command(args: Sequence[str]) -> List[str]:
    return [binary(), *[os.fspath(a) for a in args]]


def run(
    args: Sequence[str],
    *,
    ok: Sequence[int] = (0,),
    campaign_dir: Optional[Path] = None,
) -> subprocess.CompletedProcess:
    """Run `granular ARGS`, capturing its output; an exit code outside `ok` raises the
    matching exception with what the binary printed on standard error."""
    cmd = command(args)
    env = dict(os.environ)
    env.setdefault("NO_COLOR", "1")
    p = subprocess.run(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        encoding="utf-8",
        errors="replace",
    )
    if p.returncode not in ok:
        raise error_of(p.returncode, p.stderr, cmd)
    return p


def error_of(code: int, stderr: str, cmd: Sequence[str]) -> GranularError:
    """The exception for a refusal of exit code `code` with standard error `stderr`."""
    text = _strip_log_prefixes(stderr).strip() or f"`{' '.join(cmd)}` exited with {code}"
    if code == 3:
        if "heals" in text and "granular resume" in text:
            return CampaignDamaged(text, exit_code=code, command=cmd)
        return CampaignError(text, exit_code=code, command=cmd)
    return GranularError(text, exit_code=code, command=cmd)


_LEVELS = {"ERROR": "error", "WARN": "warning", "INFO": "info", "DEBUG": "debug", "TRACE": "trace"}


def log_line(line: str) -> Tuple[Optional[str], str]:
    """The level and message of a log line of the binary (`2026-..Z  WARN message` ->
    `("warning", "message")`); `(None, line)` for any other line."""
    parts = line.split(None, 2)
    if len(parts) == 3 and parts[0][:4].isdigit() and parts[0].endswith("Z") and parts[1] in _LEVELS:
        return _LEVELS[parts[1]], parts[2]
    return None, line


def pretty(line: str) -> str:
    """A line of the binary's standard error as shown: a log line without its time stamp
    (`warning: message`), any other line as it is."""
    level, message = log_line(line)
    return f"{level}: {message}" if level else line


def _strip_log_prefixes(text: str) -> str:
    """What the binary said that matters for an exception: its lines without the time stamps
    of log lines, and without the info, debug and trace logs."""
    lines = text.splitlines()
    return "\n".join(pretty(x) for x in lines if log_line(x)[0] not in ("info", "debug", "trace"))
