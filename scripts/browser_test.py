#!/usr/bin/env python3
"""The report and the live dashboard in a real browser (headless Chromium), standard library only.

Usage: browser_test.py GRANULAR_BIN CHROMIUM OUT_DIR

1. Report: a small DSMC campaign (2 points x 2 replicas, under a second) is run and reported;
   `chromium --headless --dump-dom` of the file must hold one <svg> per figure the report says it
   drew (the DOM as the browser parsed it: a malformed page loses elements), every section, and
   `--screenshot` writes OUT_DIR/report.png (checked to be a non-blank PNG).
2. Dashboard: a slower campaign (3 runs of a few seconds each, one thread) is started in the
   background by `granular run`, `granular serve` serves it on an ephemeral loopback port, and
   Chromium, driven over the DevTools protocol on a pipe (--remote-debugging-pipe), loads the
   page once and reads the progress line the page's script updates while the other process
   runs. It must see a run running and later more runs done than when the page loaded (without
   a reload: the live update), then every run done and the figures. Screenshots
   OUT_DIR/serve-running.png and OUT_DIR/serve-done.png; `--dump-dom` of the served page.

Prints what it saw; exits non-zero with the reason on any failure.
"""

import base64
import fcntl
import json
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
import zlib

BIN, CHROMIUM, OUT = sys.argv[1], sys.argv[2], sys.argv[3]
os.makedirs(OUT, exist_ok=True)
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
         "--no-first-run", "--no-default-browser-check", "--hide-scrollbars"]


def fail(msg):
    print(f"browser test FAILED: {msg}", file=sys.stderr)
    sys.exit(1)


def chromium(args, timeout=120):
    with tempfile.TemporaryDirectory() as profile:
        r = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args],
                           capture_output=True, text=True, timeout=timeout)
    if r.returncode != 0:
        fail(f"chromium {' '.join(args)} exited {r.returncode}: {r.stderr[-2000:]}")
    return r.stdout


def png_check(path, what):
    """A PNG of real content: signature, size, and more than one colour in its first rows."""
    data = open(path, "rb").read()
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        fail(f"{what}: {path} is not a PNG")
    w, h = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    idat, i = b"", 8
    while i < len(data):
        n = int.from_bytes(data[i:i + 4], "big")
        if data[i + 4:i + 8] == b"IDAT":
            idat += data[i + 8:i + 8 + n]
        i += 12 + n
    raw = zlib.decompress(idat)
    distinct = len(set(raw[: min(len(raw), 400 * (w * 4 + 1))]))
    if distinct < 8:
        fail(f"{what}: {path} looks blank ({distinct} distinct byte values)")
    print(f"{what}: {path} {w}x{h} px, {len(data)} bytes")


def granular(*args, check=True):
    r = subprocess.run([BIN, *args], capture_output=True, text=True)
    if check and r.returncode != 0:
        fail(f"granular {' '.join(args)} exited {r.returncode}: {r.stderr[-2000:]}")
    return r


def manifest(path, name, replicas, n1, t_end, sweep):
    m = {
        "name": name, "model": "dsmc", "seed": 11, "replicas": replicas,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": n1, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": t_end,
            "output_times": {"log": {"from": 0.01, "to": t_end, "per_decade": 5}},
            "observables": ["temperature", "msd"],
        },
    }
    if sweep:
        m["sweep"] = {"restitution.constant": [0.7, 0.9]}
    json.dump(m, open(path, "w"))


def report_test(work):
    manifest(f"{work}/small.json", "browser-report", 2, 2000, 10.0, True)
    granular("run", f"{work}/small.json", "--out", f"{work}/small", "--quiet")
    page = f"{work}/small.html"
    r = granular("report", f"{work}/small", "--out", page)
    out = r.stdout + r.stderr
    m = re.search(r"\((\d+) figures", out)
    if not m:
        fail(f"report did not say how many figures: {out!r}")
    figures = int(m.group(1))
    dom = chromium(["--dump-dom", f"file://{page}"])
    svgs = dom.count("<svg")
    print(f"report: {figures} figures written; the browser's DOM has {svgs} <svg>, "
          f"{dom.count('<figure')} <figure>, {len(dom)} characters")
    if figures < 2 or svgs != figures or dom.count("<figure") != figures:
        fail(f"report: {figures} figures but {svgs} <svg> in the DOM")
    for section in ["campaign", "progress", "shards", "failures", "figures", "manifest"]:
        if f'id="{section}"' not in dom:
            fail(f"report: section {section} missing from the DOM")
    if "4: 4 done, 0 failed, 0 running, 0 pending" not in dom:
        fail("report: progress line missing")
    chromium(["--window-size=1280,2400", f"--screenshot={OUT}/report.png", f"file://{page}"])
    png_check(f"{OUT}/report.png", "report screenshot")


class Cdp:
    """Chrome DevTools protocol over --remote-debugging-pipe (fd 3 in, fd 4 out, NUL-framed)."""

    def __init__(self, profile):
        to_chrome_r, self.to_chrome = os.pipe()
        self.from_chrome, from_chrome_w = os.pipe()
        # Chromium reads fd 3 and writes fd 4: in the child, both ends are first moved above
        # 10 (so that neither overwrites the other), then onto 3 and 4, which pass_fds keeps
        # open (the close_fds step runs after preexec_fn).
        def fds():
            r = fcntl.fcntl(to_chrome_r, fcntl.F_DUPFD, 10)
            w = fcntl.fcntl(from_chrome_w, fcntl.F_DUPFD, 10)
            os.dup2(r, 3)
            os.dup2(w, 4)
        self.proc = subprocess.Popen(
            [CHROMIUM, *FLAGS, "--remote-debugging-pipe", f"--user-data-dir={profile}",
             "--window-size=1280,2400", "about:blank"],
            pass_fds=(3, 4), preexec_fn=fds,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self.buf, self.next_id, self.session = b"", 0, None

    def send(self, method, params=None, timeout=30):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if self.session:
            msg["sessionId"] = self.session
        os.write(self.to_chrome, json.dumps(msg).encode() + b"\0")
        deadline = time.time() + timeout
        while True:
            while b"\0" in self.buf:
                raw, self.buf = self.buf.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self.next_id:
                    if "error" in reply:
                        fail(f"DevTools {method}: {reply['error']}")
                    return reply.get("result", {})
            left = deadline - time.time()
            if left <= 0:
                fail(f"DevTools {method}: no answer in {timeout} s")
            r, _, _ = select.select([self.from_chrome], [], [], left)
            if r:
                chunk = os.read(self.from_chrome, 1 << 20)
                if not chunk:
                    fail("chromium closed the DevTools pipe")
                self.buf += chunk

    def open_page(self, url):
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.send("Target.attachToTarget",
                                 {"targetId": target, "flatten": True})["sessionId"]
        self.send("Page.enable")
        self.send("Page.navigate", {"url": url})

    def eval(self, js):
        r = self.send("Runtime.evaluate", {"expression": js, "returnByValue": True})
        return r.get("result", {}).get("value")

    def screenshot(self, path):
        data = self.send("Page.captureScreenshot", {"format": "png"})["data"]
        open(path, "wb").write(base64.b64decode(data))

    def close(self):
        self.proc.kill()
        self.proc.wait()


def counts(text):
    m = re.search(r"(\d+) done, (\d+) failed, (\d+) running, (\d+) pending", text or "")
    return tuple(int(x) for x in m.groups()) if m else None


def serve_test(work):
    # 3 runs of several seconds each on one thread (~5 s on a fast 2026 core): the page is
    # loaded while the first runs, and a run outlasts the 2 s heartbeat and the page's 2 s
    # poll (N_1 = 1e6 to t = 100, ~1.5 s there, let a page see no run running).
    manifest(f"{work}/slow.json", "browser-serve", 3, 2000000, 1000.0, False)
    camp = f"{work}/slow"
    log = open(f"{work}/run.log", "w")
    run = subprocess.Popen([BIN, "run", f"{work}/slow.json", "--out", camp, "--threads", "1",
                            "--flush-every", "0.2"],
                           stdout=log, stderr=subprocess.STDOUT)
    serve = cdp = None
    try:
        deadline = time.time() + 60
        while granular("status", camp, check=False).returncode != 0:
            if time.time() > deadline:
                fail("the background campaign never became readable")
            time.sleep(0.1)
        serve = subprocess.Popen([BIN, "serve", camp, "--addr", "127.0.0.1:0"],
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        url = None
        deadline = time.time() + 30
        while url is None and time.time() < deadline:
            line = serve.stdout.readline()
            if not line:
                fail("granular serve exited before saying where it serves")
            m = re.search(r"(http://127\.0\.0\.1:\d+/)", line)
            url = m and m.group(1)
        if not url:
            fail("granular serve did not print its address")
        print(f"serve: {url}")
        with tempfile.TemporaryDirectory() as profile:
            cdp = Cdp(profile)
            cdp.open_page(url)
            seen, shot_running = [], False
            deadline = time.time() + 240
            while time.time() < deadline:
                c = counts(cdp.eval(
                    "(document.getElementById('progress-counts')||{}).textContent"))
                if c and (not seen or seen[-1] != c):
                    seen.append(c)
                    print(f"serve: the page shows {c[0]} done, {c[1]} failed, {c[2]} running, "
                          f"{c[3]} pending")
                if c and c[2] > 0 and not shot_running:
                    cdp.screenshot(f"{OUT}/serve-running.png")
                    shot_running = True
                if c and c[0] == 3:
                    break
                time.sleep(0.25)
            if not seen:
                fail("the served page never showed the progress line")
            if not any(c[2] > 0 for c in seen):
                fail(f"the page never showed a run running: {seen}")
            if seen[-1][0] != 3 or seen[0][0] >= 3:
                fail(f"the page did not follow the runs to the end: {seen}")
            # The figures arrive with the finished runs (the page updates them or reloads).
            deadline = time.time() + 60
            svgs = 0
            while time.time() < deadline:
                svgs = cdp.eval("document.querySelectorAll('#sec-figures svg').length") or 0
                if svgs >= 2:
                    break
                time.sleep(0.5)
            if svgs < 2:
                fail(f"the served page shows {svgs} figures once every run is done")
            head = cdp.eval("(document.getElementById('headline')||{}).textContent")
            if not head or "3 of 3 runs done" not in head or "complete" not in head:
                fail(f"the headline did not follow the runs: {head!r}")
            print(f"serve: headline: {head}")
            print(f"serve: {svgs} figures on the page once every run was done "
                  f"({len(seen)} states seen without a reload)")
            cdp.screenshot(f"{OUT}/serve-done.png")
            png_check(f"{OUT}/serve-done.png", "dashboard screenshot")
            if shot_running:
                png_check(f"{OUT}/serve-running.png", "dashboard screenshot while running")
        dom = chromium(["--dump-dom", url])
        if dom.count("<svg") < 2 or counts(dom) is None or counts(dom)[0] != 3:
            fail("--dump-dom of the served page: figures or progress missing")
        print(f"serve: --dump-dom of the served page: {dom.count('<svg')} <svg>, "
              f"progress {counts(dom)}")
    finally:
        if cdp:
            cdp.close()
        if serve:
            serve.send_signal(signal.SIGINT)
            try:
                serve.wait(10)
            except subprocess.TimeoutExpired:
                serve.kill()
        if run.poll() is None:
            run.kill()
        run.wait()
    if run.returncode != 0:
        fail(f"the background campaign exited {run.returncode}: {open(f'{work}/run.log').read()[-2000:]}")


def main():
    with tempfile.TemporaryDirectory() as work:
        report_test(work)
        if len(sys.argv) > 4 and sys.argv[4] == "--report-only":
            return
        serve_test(work)
    print("browser test: passed")


main()
