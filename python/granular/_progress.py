"""Running `granular run`/`resume` with its progress shown: an HTML bar updated in place in a
notebook (Jupyter, VS Code), a one-line bar on a terminal, nothing otherwise.

The binary reports progress with `--progress-json`: one JSON object per line on standard error,
`{"progress": {"total", "finished", "failed", "running", "fraction"}}`; every other line (logs,
warnings, errors) is passed on to Python's standard error and kept for the exception.
"""

from __future__ import annotations

import html
import json
import os
import signal
import subprocess
import sys
import threading
import time
from typing import List, Optional, Sequence, Tuple

from ._binary import pretty


def _in_notebook() -> bool:
    ip = sys.modules.get("IPython")
    if ip is None:
        return False
    try:
        shell = ip.get_ipython()  # type: ignore[attr-defined]
    except Exception:
        return False
    return shell is not None and type(shell).__name__ != "TerminalInteractiveShell"


class _Display:
    def __init__(self, mode: str, label: str) -> None:
        self.mode = mode
        self.label = label
        self.handle = None
        self.t0 = time.monotonic()
        self.last = ""
        if mode == "notebook":
            from IPython.display import HTML, display  # type: ignore

            self.handle = display(HTML(self._html(None)), display_id=True)

    def _html(self, p: Optional[dict]) -> str:
        label = html.escape(self.label)
        if p is None:
            return f"<div><b>{label}</b>: starting</div>"
        total = max(int(p.get("total", 0)), 0)
        frac = float(p.get("fraction", 0.0))
        failed = int(p.get("failed", 0))
        fail = f", <span style='color:#b00'>{failed} failed</span>" if failed else ""
        return (
            f"<div><b>{label}</b> <progress value='{frac:.4f}' max='1' style='width:40%'></progress> "
            f"{100 * frac:.0f}%: {int(p.get('finished', 0))}/{total} runs finished, "
            f"{int(p.get('running', 0))} running{fail}, {time.monotonic() - self.t0:.0f} s</div>"
        )

    def update(self, p: dict) -> None:
        if self.mode == "notebook" and self.handle is not None:
            from IPython.display import HTML  # type: ignore

            self.handle.update(HTML(self._html(p)))
        elif self.mode == "terminal":
            frac = float(p.get("fraction", 0.0))
            n = int(30 * min(max(frac, 0.0), 1.0))
            line = (
                f"\r{self.label} [{'#' * n}{'.' * (30 - n)}] {100 * frac:3.0f}% "
                f"{int(p.get('finished', 0))}/{int(p.get('total', 0))} runs, "
                f"{int(p.get('running', 0))} running"
            )
            if int(p.get("failed", 0)):
                line += f", {int(p['failed'])} failed"
            sys.stderr.write(line.ljust(len(self.last)))
            sys.stderr.flush()
            self.last = line

    def message(self, line: str) -> None:
        if self.mode == "terminal" and self.last:
            sys.stderr.write("\n")
            self.last = ""
        sys.stderr.write(line + "\n")
        sys.stderr.flush()

    def close(self) -> None:
        if self.mode == "terminal" and self.last:
            sys.stderr.write("\n")
            sys.stderr.flush()


def _terminate_with_parent() -> None:  # pragma: no cover (runs in the child)
    """In the child before exec (Linux): SIGTERM when the parent dies (PR_SET_PDEATHSIG)."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def run_with_progress(
    cmd: Sequence[str], *, progress: Optional[bool], label: str
) -> Tuple[int, str, str]:
    """Run `cmd` (a `run`/`resume` command with `--progress-json`); returns its exit code, its
    standard output and its standard error without the progress lines. Ctrl-C (a notebook's
    interrupt) is passed on to the binary, which checkpoints and stops; the exit code is then
    130."""
    if progress is None:
        mode = "notebook" if _in_notebook() else ("terminal" if sys.stderr.isatty() else "none")
    elif progress:
        mode = "notebook" if _in_notebook() else "terminal"
    else:
        mode = "none"
    env = dict(os.environ)
    env.setdefault("NO_COLOR", "1")
    proc = subprocess.Popen(
        list(cmd),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        env=env,
        encoding="utf-8",
        errors="replace",
        bufsize=1,
        # Its own session: a terminal's Ctrl-C reaches only Python, which passes it on once
        # (the binary then checkpoints and stops; a second signal would stop it at once).
        start_new_session=True,
        # And if Python dies (a notebook kernel restarted or killed), the binary is sent
        # SIGTERM: it checkpoints and stops instead of running on, holding the campaign's lock.
        preexec_fn=_terminate_with_parent if sys.platform.startswith("linux") else None,
    )
    out: List[str] = []
    reader = threading.Thread(target=lambda: out.append(proc.stdout.read()), daemon=True)
    reader.start()
    kept: List[str] = []
    interrupted = False
    display: Optional[_Display] = None
    code: Optional[int] = None
    try:
        # Every step under one handler: a Ctrl-C while a line is drawn (a notebook's display
        # update goes through ZMQ) is passed on like one while waiting for a line.
        while True:
            try:
                if display is None:
                    display = _Display(mode, label)
                line = proc.stderr.readline()
                if not line:
                    break
                line = line.rstrip("\n")
                if line.startswith('{"progress"'):
                    try:
                        display.update(json.loads(line)["progress"])
                        continue
                    except (ValueError, KeyError, TypeError):
                        pass
                kept.append(line)
                if mode != "none":
                    display.message(pretty(line))
            except KeyboardInterrupt:
                if not interrupted:
                    interrupted = True
                    proc.send_signal(signal.SIGINT)
        while code is None:
            try:
                code = proc.wait()
            except KeyboardInterrupt:
                if not interrupted:
                    interrupted = True
                    proc.send_signal(signal.SIGINT)
    finally:
        if display is not None:
            display.close()
        if code is None and proc.poll() is None:
            # An error of this module (not an interrupt, which is passed on above): stop the
            # binary the way Ctrl-C does, so it checkpoints, then wait for it.
            proc.send_signal(signal.SIGINT)
            proc.wait()
    reader.join()
    return code, "".join(out), "\n".join(kept)
