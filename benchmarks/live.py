"""Benchmark: the live view with N agents in headless Chromium.

Run: ``python benchmarks/live.py [--agents 100 1000 10000] [--seconds 6]
[--shots docs/img]``. For each N, unicycles on constant random commands
run live at real time (dt = 0.05 s, trails 3 s); a headless Chromium
(Debian's, software WebGL through SwiftShader: no GPU) opens the page and,
over ``--seconds``, the script measures

- browser frames/s: ``requestAnimationFrame`` callbacks counted in the page;
- scene updates/s: agent updates the server sent (``LiveView.draws``);
- page lag: simulated time minus the time the page shows (the status text
  is refreshed 4 times a second, so up to 0.25 s of it is by design);
- real-time factor of the simulation while it is drawn;
- paused page frames/s: the same page paused (no scene updates), for
  comparison.

Prints a markdown table. Not part of the test suite.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "viz"))

import avblocks as av  # noqa: E402
from avblocks.viz.live import LiveView  # noqa: E402


def make_diagram(n, seed=0):
    rng = np.random.default_rng(seed)
    half = 5.0 * np.sqrt(n)
    pose0 = np.c_[rng.uniform(-half, half, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    cmd = np.c_[rng.uniform(0.5, 2.0, n), rng.uniform(-0.5, 0.5, n)]
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
    c = d.add(av.blocks.Constant(cmd), name="c")
    g = d.add(av.blocks.Gain(1.0), name="speed")
    d.connect(c.y, g.u)
    d.connect(g.y, f.cmd)
    return d


def browser():
    from test_live import _browser
    return _browser()


def page_time(drv):
    m = re.search(r"t = ([0-9.]+) s", drv.find_element("tag name", "body").text)
    return float(m.group(1)) if m else None


def measure(drv, n, seconds, shots, trail=3.0, trail_style="dots", dpr=None):
    view = LiveView(make_diagram(n), t_final=120.0, dt=0.05, realtime=1.0, trail=trail,
                    trail_style=trail_style,
                    verbose=False, log=["fleet.pose"])
    view.start()
    try:
        drv.get(view.url + (f"?fixedDpr={dpr:g}" if dpr else ""))
        t_end = time.monotonic() + 30
        while page_time(drv) is None and time.monotonic() < t_end:
            time.sleep(0.2)
        drv.execute_script(
            "window.__n = 0; (function f(){ window.__n++; requestAnimationFrame(f); })();")
        # let the page settle (shader compilation in software GL takes seconds
        # on a loaded machine): until two 2-s windows agree within 20 %
        prev = None
        for _ in range(10):
            n0, w = drv.execute_script("return window.__n;"), time.perf_counter()
            time.sleep(2.0)
            f = (drv.execute_script("return window.__n;") - n0) / (time.perf_counter() - w)
            if prev is not None and abs(f - prev) <= 0.2 * max(f, prev):
                break
            prev = f
        n_start = drv.execute_script("return window.__n;")
        d0, k0, w0 = view.draws, view.sim.k, time.perf_counter()
        lags = []
        for _ in range(int(seconds * 2)):
            time.sleep(0.5)
            pt = page_time(drv)
            if pt is not None:
                lags.append(view.sim.t - pt)
        frames = drv.execute_script("return window.__n;") - n_start
        wall = time.perf_counter() - w0
        canvas = drv.execute_script(
            "const c = [...document.querySelectorAll('canvas')].sort((a, b) => "
            "b.width * b.height - a.width * a.height)[0]; return c ? [c.width, c.height] : null;")
        row = {"agents": n, "drawn as": "points" if n > view.points_above else "arrows",
               "browser frames/s": frames / wall,
               "scene updates/s": (view.draws - d0) / wall,
               "page lag [s]": statistics.median(lags) if lags else float("nan"),
               "real-time factor": (view.sim.k - k0) * view.sim.dt / wall,
               "canvas px": "x".join(map(str, canvas)) if canvas else "?"}
        # the same page with nothing changing: what the browser does when
        # it only has to keep its frame loop going
        view.pause()
        time.sleep(3.0)
        n1, w1 = drv.execute_script("return window.__n;"), time.perf_counter()
        time.sleep(3.0)
        row["paused page frames/s"] = ((drv.execute_script("return window.__n;") - n1)
                                       / (time.perf_counter() - w1))
        if shots:
            os.makedirs(shots, exist_ok=True)
            drv.execute_script("document.querySelectorAll('.mantine-Notification-root')"
                               ".forEach(e => e.remove());")
            drv.save_screenshot(os.path.join(shots, f"live-{n}.png"))
    finally:
        view.close()
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--agents", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--shots", default=None, help="folder for screenshots")
    ap.add_argument("--trail", type=float, default=3.0, help="trail length [s] (0: none)")
    ap.add_argument("--trail-style", default="dots", choices=("dots", "lines"))
    ap.add_argument("--dpr", type=float, default=None,
                    help="open the page with ?fixedDpr=DPR (viser: fixed render scale)")
    a = ap.parse_args()
    drv = browser()
    rows = []
    try:
        for n in a.agents:
            rows.append(measure(drv, n, a.seconds, a.shots, a.trail, a.trail_style, a.dpr))
            print(rows[-1], flush=True)
    finally:
        drv.quit()
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(f"{r[k]:.2f}" if isinstance(r[k], float) else str(r[k])
                                for k in keys) + " |")


if __name__ == "__main__":
    main()
