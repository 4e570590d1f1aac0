"""`granular.open`, `granular.run`, `granular.validate`: the binary driven from Python."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Union

from . import _binary
from .campaign import Campaign, PathLike, execute
from .errors import GranularError, ManifestError, Problem

Manifest = Union[PathLike, Mapping[str, Any]]

#: The name a manifest given as a dict has in errors.
DICT_NAME = "<manifest dict>"


def open(path: PathLike) -> Campaign:  # noqa: A001 (the API's name: granular.open)
    """The campaign in directory `path` (written by `granular run` or `granular.run`)."""
    return Campaign(path)


class _ManifestFile:
    """A manifest as a file the binary reads: the path itself, or a dict written to a
    temporary file (removed afterwards) whose name errors replace by `<manifest dict>`."""

    def __init__(self, manifest: Manifest) -> None:
        self._tmp: Optional[tempfile.TemporaryDirectory] = None
        if isinstance(manifest, Mapping):
            self._tmp = tempfile.TemporaryDirectory(prefix="granular-manifest-")
            p = Path(self._tmp.name) / "manifest.json"
            try:
                text = json.dumps(manifest, indent=2, allow_nan=False)
            except (TypeError, ValueError) as e:
                self._tmp.cleanup()
                raise ManifestError(DICT_NAME, [Problem("/", f"not representable as JSON: {e}")]) from None
            p.write_text(text)
            self.path = str(p)
            self.name = DICT_NAME
        elif isinstance(manifest, (str, os.PathLike)):
            self.path = os.fspath(manifest)
            self.name = self.path
        else:
            raise TypeError(f"a manifest is a path or a dict, not {type(manifest).__name__}")

    def rename(self, text: str) -> str:
        return text.replace(self.path, self.name) if self._tmp is not None else text

    def __enter__(self) -> "_ManifestFile":
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()


def _validate(mf: _ManifestFile) -> Dict[str, Any]:
    args = ["validate", mf.path, "--json"]
    p = _binary.run(args, ok=(0, 2))
    try:
        v = json.loads(p.stdout)
    except ValueError:
        raise GranularError(mf.rename(p.stderr.strip() or "granular validate printed no JSON"), exit_code=p.returncode) from None
    if not v.get("valid"):
        errs = [Problem(e.get("path") or "/", mf.rename(e.get("message", ""))) for e in v.get("errors", [])]
        raise ManifestError(mf.name, errs, exit_code=p.returncode)
    v["file"] = mf.name
    v["warnings"] = [mf.rename(w) for w in v.get("warnings", [])]
    return v


def validate(manifest: Manifest) -> Dict[str, Any]:
    """Check a manifest (a path or a dict) with `granular validate`; returns what it found
    (`campaign`: name, model, points, runs; `warnings`) or raises `ManifestError` carrying
    every error with its JSON path (`e.errors[i].path`, `.message`)."""
    with _ManifestFile(manifest) as mf:
        return _validate(mf)


def run(
    manifest: Manifest,
    out: PathLike,
    *,
    threads: Optional[int] = None,
    progress: Optional[bool] = None,
    check: bool = True,
) -> Campaign:
    """Run a campaign (`granular run MANIFEST --out OUT`) and return it.

    `manifest` is a path or a dict; it is validated first, and an invalid one raises
    `ManifestError` with every error and its JSON path, writing nothing. A directory that
    holds the same campaign is continued (or grown, if the manifest asks for more).
    `threads`: worker threads (default all cores). `progress`: show progress (default: in a
    notebook and on a terminal). `check`: raise `RunsFailed` when runs failed (the campaign is
    in the exception); with `check=False` the campaign is returned. Ctrl-C (or a notebook's
    interrupt) checkpoints and raises `Interrupted`; `Campaign.resume()` continues.
    """
    out_path = Path(os.fspath(out))
    with _ManifestFile(manifest) as mf:
        v = _validate(mf)
        label = str(v.get("campaign", {}).get("name") or out_path)
        try:
            return execute(
                ["run", mf.path, "--out", out_path], out_path, threads=threads, progress=progress, check=check, label=label
            )
        except GranularError as e:
            e.message = mf.rename(e.message)
            e.args = (e.message,)
            raise
