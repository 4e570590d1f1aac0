#!/usr/bin/env python3
"""Run docs/tutorial.md as a test, so that it never rots.

Usage: .venv/bin/python scripts/tutorial_test.py [GRANULAR_BINARY] [TUTORIAL_MD]
(defaults: target/release/granular, docs/tutorial.md; run from anywhere).

The tutorial marks what is executed with the info string of its fenced blocks:

- ```sh run        a shell block, run with `bash -euo pipefail` in a temporary directory that
                   holds a copy of the repository's `jobs/`, with `granular` (the binary given)
                   and `python` (this interpreter, the repository's .venv) first on PATH, and
                   `import granular` finding the repository's python/ package (running the
                   binary given, through GRANULAR_BIN); the
                   blocks run in order and share that directory. A block that exits non-zero
                   fails the test.
- ```text output   what the preceding `sh run` block printed (stdout and stderr together). Every
                   line shown, except a line `...`, must be found in what the block printed, in
                   the same order (lines printed in between are skipped): its words exactly,
                   and its numbers within a relative tolerance of 0.1 % (the campaign is
                   deterministic; the tolerance only absorbs how a library rounds).

Other blocks (```sh, ```json, ```python, ```sql) are shown to the reader and not run; a
```json file=PATH block is written to PATH in the temporary directory before the next `sh run`
block, and must be identical (as JSON) to the repository's file of that path if there is one.
Exit status 0 when every block passed, 1 with the first failure explained otherwise.
"""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

REL_TOL = 1e-3
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def blocks(text):
    """The fenced blocks of a Markdown text: (info string, body, line number of the fence)."""
    out, lines, i = [], text.split("\n"), 0
    while i < len(lines):
        m = re.match(r"^```(.*)$", lines[i])
        if m:
            info, start, body = m.group(1).strip(), i + 1, []
            i += 1
            while i < len(lines) and not lines[i].startswith("```"):
                body.append(lines[i])
                i += 1
            if i == len(lines):
                raise SystemExit(f"tutorial line {start}: a fenced block is not closed")
            out.append((info, "\n".join(body) + "\n", start))
        i += 1
    return out


def tokens(line):
    """Words and numbers of a line; numbers as floats."""
    out, pos = [], 0
    for m in NUMBER.finditer(line):
        out += line[pos:m.start()].split()
        out.append(float(m.group()))
        pos = m.end()
    out += line[pos:].split()
    return out


def same(a, b):
    if isinstance(a, float) and isinstance(b, float):
        return abs(a - b) <= REL_TOL * max(abs(a), abs(b)) or a == b
    return a == b


def line_matches(expected, actual):
    """The tokens of `expected` occur contiguously in `actual` (a log line's time stamp and
    level before them are allowed)."""
    e, a = tokens(expected), tokens(actual)
    if not e:
        return True
    for s in range(len(a) - len(e) + 1):
        if all(same(x, y) for x, y in zip(e, a[s:s + len(e)])):
            return True
    return False


def check_output(expected, actual):
    """None if every expected line is found in order, else why not."""
    got = actual.split("\n")
    at = 0
    for want in expected.split("\n"):
        if not want.strip() or want.strip() == "...":
            continue
        while at < len(got) and not line_matches(want, got[at]):
            at += 1
        if at == len(got):
            return f"this line of the tutorial's output was not printed (in this order):\n    {want}"
        at += 1
    return None


def main():
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    binary = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(repo, "target/release/granular"))
    md = os.path.abspath(sys.argv[2] if len(sys.argv) > 2 else os.path.join(repo, "docs/tutorial.md"))
    if not os.access(binary, os.X_OK):
        raise SystemExit(f"tutorial-test: {binary} is not an executable; build it (cargo build --release)")
    text = open(md).read()
    work = tempfile.mkdtemp(prefix="tutorial-")
    try:
        bindir = os.path.join(work, ".bin")
        os.mkdir(bindir)
        os.symlink(binary, os.path.join(bindir, "granular"))
        # A wrapper, not a link: a link to a virtualenv's python outside it loses the venv.
        with open(os.path.join(bindir, "python"), "w") as f:
            f.write(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
        os.chmod(os.path.join(bindir, "python"), 0o755)
        shutil.copytree(os.path.join(repo, "jobs"), os.path.join(work, "jobs"))
        env = dict(os.environ, PATH=bindir + os.pathsep + os.environ.get("PATH", ""))
        # `import granular` in the tutorial's Python is this checkout's package (python/),
        # running the binary given (scripts/python-test.sh tests the installed wheel).
        env["PYTHONPATH"] = os.path.join(repo, "python") + (
            os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        env["GRANULAR_BIN"] = binary
        env.pop("GRANULAR_LOG", None)
        last, ran, checked = None, 0, 0
        for info, body, line in blocks(text):
            words = info.split()
            kind = words[0] if words else ""
            if kind == "sh" and "run" in words[1:]:
                print(f"tutorial-test: line {line}: {body.strip().splitlines()[0]}", flush=True)
                p = subprocess.run(["bash", "-euo", "pipefail", "-c", body], cwd=work, env=env,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                   timeout=600)
                last = (line, p.stdout)
                ran += 1
                if p.returncode != 0:
                    print(p.stdout)
                    raise SystemExit(f"tutorial-test: FAILED: the block at {md}:{line} exited with {p.returncode}")
            elif kind == "text" and "output" in words[1:]:
                if last is None:
                    raise SystemExit(f"tutorial-test: {md}:{line}: an output block before any `sh run` block")
                why = check_output(body, last[1])
                checked += 1
                if why:
                    print(last[1])
                    raise SystemExit(f"tutorial-test: FAILED: {md}:{line}: the output of the block at line {last[0]} differs: {why}")
                last = None
            elif kind == "json" and any(w.startswith("file=") for w in words[1:]):
                path = next(w for w in words[1:] if w.startswith("file="))[5:]
                data = json.loads(body)
                repo_file = os.path.join(repo, path)
                if os.path.exists(repo_file) and json.load(open(repo_file)) != data:
                    raise SystemExit(f"tutorial-test: FAILED: {md}:{line}: the JSON shown is not {path} of the repository")
                os.makedirs(os.path.dirname(os.path.join(work, path)) or work, exist_ok=True)
                with open(os.path.join(work, path), "w") as f:
                    f.write(body)
        if ran == 0 or checked == 0:
            raise SystemExit(f"tutorial-test: FAILED: {md} has no `sh run` or no `text output` blocks")
        print(f"tutorial-test: ok ({ran} blocks run, {checked} outputs checked)")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
