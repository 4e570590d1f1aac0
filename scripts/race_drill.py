#!/usr/bin/env python3
"""The race drill: many `granular` commands at once on one campaign, SIGKILL at random moments.

Usage: python scripts/race_drill.py BIN WORKDIR [--minutes M] [--workers N] [--seed S]
       (scripts/race-drill.sh sets it up)

For M minutes (default 10), N worker threads (default 4) each run, one after another, a random
command on one small DSMC campaign: `run` with a random grown manifest (restitution values from
a fixed set, 1-3 replicas; or, a fifth of the time, values of another set with a list of seeds;
an occasional longer t_end), `resume` (whole or
one shard of 2), `compact`, `status --json`, `verify`, `report`, `plan`, `upgrade`. A command is
killed with SIGKILL after a random delay with probability --kill (default 0.2).

Every command must end with an expected exit code: 0; 3 (refused: the directory is locked by
another live command, or a shorter run asked); 1 is a failed run (not expected here: the
physics is tame); 4 (I/O) or a panic (101), a hang (over --hang seconds) or anything else fails
the drill. `verify` may also say 3 while another command writes (a part not yet committed, a
live compaction).

At the end: a growth to every replicated value with 3 replicas (`run`, must exit 0), so the
comparison covers the runs the drill made; `resume` until it exits 0, then the campaign must equal (scripts/compare_tables.py
--current) a campaign run directly from its final manifest (DIR/manifest.json), `verify` must
exit 0, and nothing in the sibling directory `outside/` (files planted next to the campaign,
and reachable through a symbolic link that the drill plants in the campaign once, at the
start: `DIR/tables/stray -> ../../outside`) may have changed.

Prints the number of commands, of kills, the exit codes by command, and PASS or FAIL.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

RESTITUTIONS = [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]


# Points run with given seeds (a campaign never counts those runs as replicas later: a
# manifest with replicas for such a point is refused), apart from those run with replicas.
SEEDED = [0.35, 0.65, 0.95]


def manifest(rng: random.Random, t_end: float) -> dict:
    seeded = rng.random() < 0.2
    values = sorted(rng.sample(SEEDED if seeded else RESTITUTIONS, rng.randint(1, 3)))
    m = {
        "name": "race-drill",
        "model": "dsmc",
        "seed": 2026,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.5},
            "t_end": t_end,
            "output_times": {"list": [1.0, 5.0]},
            "observables": ["temperature", "msd"],
        },
        "sweep": {"restitution.constant": values},
    }
    if seeded:
        m["seeds"] = rng.sample([1, 2, 3, 5, 8, 13], rng.randint(1, 3))
    else:
        m["replicas"] = rng.randint(1, 3)
    return m


def tree_hash(d: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(d.rglob("*")):
        st = os.lstat(p)
        h.update(str(p.relative_to(d)).encode())
        h.update(f"{st.st_mode} {st.st_size} {st.st_mtime_ns}".encode())
        if p.is_file() and not p.is_symlink():
            h.update(p.read_bytes())
    return h.hexdigest()


class Drill:
    def __init__(self, args):
        self.bin = args.bin
        self.work = Path(args.workdir).resolve()
        self.dir = self.work / "campaign"
        self.outside = self.work / "outside"
        self.args = args
        self.lock = threading.RLock()
        self.ops = Counter()
        self.codes = Counter()
        self.kills = 0
        self.failures: list[str] = []
        self.deadline = time.monotonic() + args.minutes * 60
        self.t_end = 5.0
        self.serial = 0

    def log(self, msg: str) -> None:
        with self.lock:
            print(msg, flush=True)

    def command(self, rng: random.Random, wid: int) -> tuple[str, list[str]]:
        d = str(self.dir)
        r = rng.random()
        if r < 0.35:
            with self.lock:
                self.serial += 1
                n = self.serial
                if rng.random() < 0.03:
                    self.t_end = 10.0
                t_end = self.t_end
            path = self.work / "manifests" / f"m{n:05d}.json"
            path.write_text(json.dumps(manifest(rng, t_end)))
            threads = str(rng.randint(1, 2))
            return "run", ["run", str(path), "--out", d, "--threads", threads, "--quiet",
                           "--flush-every", "0", "--checkpoint-every", "0.05"]
        if r < 0.55:
            shard = rng.choice([None, None, "1/2", "2/2"])
            extra = ["--shard", shard] if shard else []
            return "resume", ["resume", d, "--quiet", "--threads", "1", "--flush-every", "0",
                              "--checkpoint-every", "0.05", *extra]
        if r < 0.63:
            return "compact", ["compact", d]
        if r < 0.73:
            return "status", ["status", d, "--json"]
        if r < 0.83:
            return "verify", ["verify", d]
        if r < 0.90:
            return "report", ["report", d, "--out", str(self.work / f"report-{wid}.html")]
        if r < 0.97:
            path = self.work / "manifests" / f"plan-{wid}.json"
            with self.lock:
                t_end = self.t_end
            path.write_text(json.dumps(manifest(rng, t_end)))
            return "plan", ["plan", str(path), "--out", d]
        return "upgrade", ["upgrade", d]

    def expected(self, name: str, code: int) -> bool:
        if code == 0:
            return True
        if code == 3:
            return True  # refused: locked by another live command (or a shorter run)
        return False

    def worker(self, wid: int) -> None:
        rng = random.Random(self.args.seed * 1000 + wid)
        while time.monotonic() < self.deadline and not self.failures:
            name, argv = self.command(rng, wid)
            kill_after = rng.uniform(0.0, 0.6) if rng.random() < self.args.kill else None
            logf = self.work / "logs" / f"w{wid}.log"
            with open(logf, "a") as lf:
                lf.write(f"\n$ granular {' '.join(argv)}\n")
                lf.flush()
                p = subprocess.Popen([self.bin, *argv], stdout=lf, stderr=lf,
                                     stdin=subprocess.DEVNULL)
                start = time.monotonic()
                killed = False
                while p.poll() is None:
                    el = time.monotonic() - start
                    if kill_after is not None and el >= kill_after and not killed:
                        p.send_signal(signal.SIGKILL)
                        killed = True
                    if el > self.args.hang:
                        p.kill()
                        p.wait()
                        self.failures.append(f"w{wid}: granular {' '.join(argv)} hung for {el:.0f} s")
                        return
                    time.sleep(0.005)
                code = p.returncode
                lf.write(f"[exit {code}{' (killed)' if killed else ''}]\n")
            with self.lock:
                self.ops[name] += 1
                if killed and code == -signal.SIGKILL:
                    self.kills += 1
                    self.codes[(name, "killed")] += 1
                    continue
                self.codes[(name, code)] += 1
            if not self.expected(name, code):
                tail = logf.read_text()[-3000:]
                self.failures.append(
                    f"w{wid}: granular {' '.join(argv)} exited {code}\n--- log tail ---\n{tail}")

    def final(self) -> None:
        d = str(self.dir)
        logf = self.work / "logs" / "final.log"
        # Grow to every replicated value with 3 replicas, so that the comparison below covers
        # the runs the drill made (not only the last random manifest's few).
        whole = manifest(random.Random(0), self.t_end)
        whole.pop("seeds", None)
        whole["replicas"] = 3
        whole["sweep"]["restitution.constant"] = RESTITUTIONS
        path = self.work / "manifests" / "final.json"
        path.write_text(json.dumps(whole))
        with open(logf, "a") as lf:
            code = subprocess.call([self.bin, "run", str(path), "--out", d, "--quiet"],
                                   stdout=lf, stderr=lf)
        if code != 0:
            self.failures.append(f"the final growth exited {code}; see {logf}")
            return
        for attempt in range(5):
            with open(logf, "a") as lf:
                code = subprocess.call([self.bin, "resume", d, "--quiet"], stdout=lf, stderr=lf)
            if code == 0:
                break
        else:
            self.failures.append(f"final resume did not exit 0 (last {code}); see {logf}")
            return
        with open(logf, "a") as lf:
            code = subprocess.call([self.bin, "verify", d], stdout=lf, stderr=lf)
        if code != 0:
            self.failures.append(f"final verify exited {code}; see {logf}")
        st = json.loads(subprocess.check_output([self.bin, "status", d, "--json"]))
        if st["current"]["done"] + st["current"]["failed"] != st["current_runs"]:
            self.failures.append(f"status after the final resume is not complete: {st}")
        direct = self.work / "direct"
        with open(logf, "a") as lf:
            code = subprocess.call([self.bin, "run", str(self.dir / "manifest.json"), "--out",
                                    str(direct), "--quiet"], stdout=lf, stderr=lf)
        if code != 0:
            self.failures.append(f"the direct campaign exited {code}; see {logf}")
            return
        here = Path(__file__).resolve().parent
        r = subprocess.run([sys.executable, str(here / "compare_tables.py"), d, str(direct),
                            "--current"], capture_output=True, text=True)
        print(r.stdout, end="")
        if r.returncode != 0:
            self.failures.append("the campaign differs from the direct campaign of its final manifest")

    def main(self) -> int:
        for sub in ("manifests", "logs", "outside"):
            (self.work / sub).mkdir(parents=True, exist_ok=True)
        (self.outside / "secret.txt").write_text("not granular's\n")
        (self.outside / ".x.pending").write_text("not granular's either\n")
        (self.outside / "part-s1of1-00000001.parquet").write_text("a stray file\n")
        first = self.work / "manifests" / "m00000.json"
        first.write_text(json.dumps(manifest(random.Random(self.args.seed), self.t_end)))
        subprocess.check_call([self.bin, "run", str(first), "--out", str(self.dir), "--quiet"])
        # A hostile link inside the campaign, pointing out of it.
        os.symlink("../../outside", self.dir / "tables" / "stray")
        before = tree_hash(self.outside)
        t0 = time.monotonic()
        threads = [threading.Thread(target=self.worker, args=(w,)) for w in range(self.args.workers)]
        for t in threads:
            t.start()
        last = t0
        while any(t.is_alive() for t in threads):
            time.sleep(1)
            if time.monotonic() - last > 60:
                last = time.monotonic()
                with self.lock:
                    self.log(f"[{(last - t0) / 60:.0f} min] {sum(self.ops.values())} commands, "
                             f"{self.kills} kills")
        for t in threads:
            t.join()
        took = time.monotonic() - t0
        if not self.failures:
            self.final()
        if tree_hash(self.outside) != before:
            self.failures.append("the directory outside the campaign changed")
        print(f"race drill: {sum(self.ops.values())} commands in {took / 60:.1f} min "
              f"({self.args.workers} at a time), {self.kills} killed with SIGKILL")
        for name in sorted(self.ops):
            codes = ", ".join(f"{c}: {n}" for (o, c), n in sorted(self.codes.items(), key=str)
                              if o == name)
            print(f"  {name:8} {self.ops[name]:5}   exits {codes}")
        if self.failures:
            for f in self.failures:
                print(f"FAIL {f}")
            return 1
        print("PASS: final resume, verify clean, equal to the direct campaign, nothing outside changed")
        return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("bin")
    ap.add_argument("workdir")
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--workers", type=int, default=4)
    ap.add_argument("--kill", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hang", type=float, default=300.0)
    sys.exit(Drill(ap.parse_args()).main())
