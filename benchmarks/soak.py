"""Soak: long runs that must not leak memory, fall behind or lose results.

1. Robots: 20 emulated robots (``avblocks robots emulate`` in a second
   process, odometry at 50 Hz) driven in circles for ``--minutes`` of wall
   time through a ``Robots`` block, paced to real time at 50 Hz
   (``dt = 0.02``), log decimated to 1 Hz. The router is a Zenoh session in
   this process.
2. NumPy engine: ``--steps`` major steps (default 10^6) of the same diagram
   with a ``vehicles.Unicycle`` in place of the robots, unpaced, log
   decimated to ``--steps / 1000`` samples.

A probe block (one more side-effect block in each diagram) samples, per
window (1 s of run time for the robots, 1/200 of the steps for the NumPy
run): the resident memory of this process (and of the emulator), the
deadline misses (a major step that started more than one period after its
slot on the wall-clock schedule) and the worst lateness. The probe keeps
its samples in arrays allocated before the run, so it does not grow
memory itself.

Verdicts, after a warm-up (the first 10 % of the windows, at least 30 s of
the robot run):

* RSS flat: the median RSS of the last third of the windows after warm-up
  is within 5 % of the median of the first third (a leak grows it; a
  single short spike, which the table shows as the highest RSS, does not);
* no deadline-miss growth: misses per window in the last third are not
  more than in the first third after warm-up plus 1 % of the steps
  (paced run only; the machine's load shows up as misses in any third);
* results complete: every logged sample is there and finite, every robot
  is fresh at the end, the run reached ``t_final``.

Run: ``python benchmarks/soak.py [--minutes 30] [--steps 1000000]
[--json out.json] [--plot benchmarks/soak.png]``; prints a markdown table.
CI runs ``--minutes 1 --steps 200000`` (about 2 minutes) through
``tests/benchmarks/test_soak.py`` (marker ``soak``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import avblocks as av
from avblocks.core.block import Block

PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def rss(pid="self"):
    """Resident memory of a process [bytes] (Linux /proc; NaN elsewhere)."""
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * PAGE
    except (OSError, ValueError, IndexError):
        return float("nan")


class Probe(Block):
    """Samples memory and step timing into preallocated windows.

    Ports: none. Side effects only: at each major step, the wall-clock
    lateness of the step against ``origin + k * period`` (the pacing
    schedule, its origin the earliest slot seen; ``period=None``: no
    lateness), and at the end of
    each window of ``window`` steps the RSS of this process and of
    ``other_pid`` (optional)."""

    side_effects = True

    def __init__(self, steps, window, period=None, other_pid=None):
        super().__init__()
        self.window, self.period, self.other = int(window), period, other_pid
        nwin = int(steps) // self.window + 2
        self.rss = np.full(nwin, np.nan)
        self.rss_other = np.full(nwin, np.nan)
        self.misses = np.zeros(nwin, np.int64)
        self.worst = np.zeros(nwin)
        self.wall = np.full(nwin, np.nan)        # wall seconds at the window's end
        self.k = 0
        self.t_first = None
        self.origin = None

    def output(self, t, x, u, xp):
        return {}

    def on_major_step(self, t, x, u, y):
        now = time.perf_counter()
        if self.t_first is None:
            self.t_first = now
        w = self.k // self.window
        if self.period is not None:
            # the schedule's origin: the earliest any step has started,
            # less its slot (so a step on time has lateness 0)
            slot = now - self.k * self.period
            self.origin = slot if self.origin is None else min(self.origin, slot)
            late = slot - self.origin
            if late > self.period:
                self.misses[w] += 1
            if late > self.worst[w]:
                self.worst[w] = late
        self.k += 1
        if self.k % self.window == 0:
            self.rss[w] = rss()
            if self.other is not None:
                self.rss_other[w] = rss(self.other)
            self.wall[w] = now - self.t_first

    def series(self):
        n = self.k // self.window
        return {"wall": self.wall[:n], "rss": self.rss[:n], "rss_other": self.rss_other[:n],
                "misses": self.misses[:n], "worst": self.worst[:n], "window": self.window}


def _diagram(fleet, n, probe):
    k = np.arange(n)
    cmd = np.column_stack([0.2 + 0.01 * (k % 5), 0.2 + 0.02 * (k % 3)])   # circles
    d = av.Diagram()
    c = d.add(av.blocks.Constant(cmd), name="c")
    f = d.add(fleet, name="fleet")
    d.connect(c.y, f.cmd)
    d.add(probe, name="probe")
    return d


def verdicts(series, warm_frac=0.1, warm_min_s=0.0, steps_per_window=None, paced=True):
    """RSS growth after warm-up and miss growth, from a probe's series."""
    wall, r = series["wall"], series["rss"]
    n = len(r)
    w0 = max(int(np.ceil(warm_frac * n)), int(np.searchsorted(wall, warm_min_s)), 1)
    w0 = min(w0, n - 1)
    base = float(r[w0 - 1])
    after = r[w0:]
    if len(after) >= 3:
        third = max(len(after) // 3, 1)
        growth = float(np.nanmedian(after[-third:]) / np.nanmedian(after[:third]) - 1.0)
    else:
        growth = float(np.nanmax(after) / base - 1.0) if len(after) else 0.0
    out = {"warmup_windows": w0, "rss_warm_MB": base / 2**20,
           "rss_end_MB": float(r[-1]) / 2**20, "rss_max_after_warm_MB":
           float(np.nanmax(after)) / 2**20 if len(after) else base / 2**20,
           "rss_growth": growth, "rss_flat": bool(growth <= 0.05)}
    if len(after) >= 3:
        if paced:       # trend per hour of wall time
            tt, unit, key = wall[w0:], 3600.0, "rss_slope_MB_per_h"
        else:           # trend per 10^6 steps
            tt = series["window"] * np.arange(w0 + 1, n + 1)
            unit, key = 1e6, "rss_slope_MB_per_Msteps"
        slope = np.polyfit(tt, after, 1)[0] if np.ptp(tt) > 0 else 0.0
        out[key] = float(slope * unit / 2**20)
    if paced:
        m = series["misses"][w0:]
        third = max(len(m) // 3, 1)
        first, last = m[:third].mean(), m[-third:].mean()
        spw = steps_per_window or series["window"]
        out.update({"misses_total": int(series["misses"].sum()),
                    "misses_per_window_first_third": float(first),
                    "misses_per_window_last_third": float(last),
                    "worst_lateness_ms": float(series["worst"].max() * 1e3),
                    "no_miss_growth": bool(last <= first + 0.01 * spw)})
    return out


def env():
    e = dict(os.environ)
    src = str(Path(__file__).resolve().parents[1] / "src")
    e["PYTHONPATH"] = src + os.pathsep + e.get("PYTHONPATH", "")
    return e


def _log_bytes(res):
    """Bytes of the run's log buffers (allocated up front, touched as the run
    logs: the one growth expected)."""
    return sum(np.asarray(v).nbytes for v in res.data.values()) + res.t.nbytes


def robots_soak(minutes, n=20, rate=50.0):
    from avblocks.interfaces.ros2 import Robots, open_router
    session, router = open_router()
    names = [f"r{i}" for i in range(n)]
    p0 = [[3.0 * (i % 5), 3.0 * (i // 5), 0.0] for i in range(n)]
    em = subprocess.Popen([sys.executable, "-m", "avblocks", "robots", "emulate", "--names",
                           ",".join(names), "--router", router, "--rate", str(rate),
                           "--pose0", json.dumps(p0)], env=env(), stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    try:
        em.stdout.readline()
        dt = 1.0 / rate
        steps = int(round(minutes * 60 * rate))
        probe = Probe(steps, window=int(rate), period=dt, other_pid=em.pid)
        robots = Robots(names, router=router, wait=30.0)
        d = _diagram(robots, n, probe)
        w0 = time.perf_counter()
        res = av.simulate(d, t_final=steps * dt, dt=dt, realtime=1.0,
                          log=["fleet.pose", "fleet.fresh", "fleet.age"],
                          log_every=int(rate), progress=False)
        wall = time.perf_counter() - w0
    finally:
        em.terminate()
        try:
            em.wait(10)
        except subprocess.TimeoutExpired:
            em.kill()
        session.close()
    s = probe.series()
    v = verdicts(s, warm_min_s=min(30.0, 0.25 * minutes * 60), steps_per_window=rate)
    expect = steps // int(rate) + 1
    complete = (len(res.t) == expect and abs(res.t[-1] - steps * dt) < 1e-6
                and bool(np.isfinite(res["fleet.pose"]).all())
                and bool(res["fleet.fresh"][-1].all()))
    v.update({"part": f"robots ({n} emulated, {rate:g} Hz, {minutes:g} min)", "steps": steps,
              "wall_s": wall, "samples": len(res.t), "samples_expected": expect,
              "results_complete": bool(complete), "overruns_meta": res.meta.get("overruns"),
              "max_lateness_meta_ms": 1e3 * res.meta.get("max_lateness", float("nan")),
              "watchdog_events": len(robots.events), "log_MB": _log_bytes(res) / 2**20,
              "stale_samples": int((~res["fleet.fresh"]).sum()),
              "emulator_rss_MB": [float(np.nanmin(s["rss_other"]) / 2**20),
                                  float(np.nanmax(s["rss_other"]) / 2**20)]})
    return v, s


def numpy_soak(steps=10**6, n=20):
    dt = 0.02
    samples = 1000
    log_every = max(steps // samples, 1)
    probe = Probe(steps, window=max(steps // 200, 1))
    p0 = np.column_stack([3.0 * (np.arange(n) % 5), 3.0 * (np.arange(n) // 5), np.zeros(n)])
    d = _diagram(av.vehicles.Unicycle(p0), n, probe)
    w0 = time.perf_counter()
    res = av.simulate(d, t_final=steps * dt, dt=dt, log=["fleet.pose"], log_every=log_every,
                      progress=False)
    wall = time.perf_counter() - w0
    s = probe.series()
    v = verdicts(s, paced=False)
    expect = steps // log_every + 1
    # the circles: the exact pose after the whole run, from the closed form
    k = np.arange(n)
    vv, ww = 0.2 + 0.01 * (k % 5), 0.2 + 0.02 * (k % 3)
    T = steps * dt
    th = ww * T
    exact = p0[:, :2] + np.column_stack([vv / ww * np.sin(th), vv / ww * (1 - np.cos(th))])
    err = float(np.abs(res["fleet.pose"][-1, :, :2] - exact).max())
    complete = (len(res.t) == expect and abs(res.t[-1] - T) < 1e-6 * T
                and bool(np.isfinite(res["fleet.pose"]).all()))
    v.update({"part": f"NumPy engine ({n} unicycles, {steps:.0e} steps)", "steps": steps,
              "wall_s": wall, "us_per_step": 1e6 * wall / steps, "samples": len(res.t),
              "samples_expected": expect, "results_complete": bool(complete),
              "final_pose_error_m": err, "log_MB": _log_bytes(res) / 2**20})
    return v, s


def table(parts):
    rows = [("wall [s]", "wall_s", "{:.1f}"), ("steps", "steps", "{:d}"),
            ("RSS at end of warm-up [MB]", "rss_warm_MB", "{:.1f}"),
            ("RSS max after warm-up [MB]", "rss_max_after_warm_MB", "{:.1f}"),
            ("RSS growth after warm-up", "rss_growth", "{:+.2%}"),
            ("RSS trend [MB/h]", "rss_slope_MB_per_h", "{:+.2f}"),
            ("RSS trend [MB per 10^6 steps]", "rss_slope_MB_per_Msteps", "{:+.2f}"),
            ("deadline misses (total)", "misses_total", "{:d}"),
            ("misses/window, first third", "misses_per_window_first_third", "{:.2f}"),
            ("misses/window, last third", "misses_per_window_last_third", "{:.2f}"),
            ("worst lateness [ms]", "worst_lateness_ms", "{:.1f}"),
            ("simulate(): overruns / worst lateness [ms]", "meta", None),
            ("watchdog events", "watchdog_events", "{:d}"),
            ("samples / expected", None, None),
            ("log buffers [MB] (part of the RSS)", "log_MB", "{:.2f}"),
            ("final pose error vs closed form [m]", "final_pose_error_m", "{:.1e}"),
            ("us per step", "us_per_step", "{:.1f}"),
            ("RSS flat (<= 5 %)", "rss_flat", "{}"), ("no miss growth", "no_miss_growth", "{}"),
            ("results complete", "results_complete", "{}")]
    lines = ["| | " + " | ".join(p["part"] for p in parts) + " |",
             "|---|" + "---:|" * len(parts)]
    for label, key, fmt in rows:
        cells = []
        for p in parts:
            if key == "meta":
                cells.append(f"{p['overruns_meta']} / {p['max_lateness_meta_ms']:.1f}"
                             if "overruns_meta" in p else "")
            elif key is None:
                cells.append(f"{p['samples']} / {p['samples_expected']}")
            elif key in p and p[key] is not None:
                cells.append(fmt.format(p[key]))
            else:
                cells.append("")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
    for (v, s), style in zip(results, ("-", "--")):
        x = s["wall"] / 60
        ax[0].plot(x, s["rss"] / 2**20, style, label=v["part"])
        if np.isfinite(s["rss_other"]).any():
            ax[0].plot(x, s["rss_other"] / 2**20, ":", label="emulator process")
        if "misses_total" in v:
            ax[1].plot(x, s["misses"], style, label="misses per second")
            ax[1].plot(x, s["worst"] * 1e3, ".", ms=2, label="worst lateness [ms]")
        else:
            steps = s["window"] * np.arange(1, len(s["rss"]) + 1)
            ax[2].plot(steps, s["rss"] / 2**20, style, label="RSS [MB]")
    ax[0].set_xlabel("wall time [min]")
    ax[0].set_ylabel("resident memory [MB]")
    ax[1].set_xlabel("wall time [min]")
    ax[1].set_title("robots run: deadline misses (50 Hz)")
    ax[2].set_xlabel("major step")
    ax[2].set_ylabel("resident memory [MB]")
    ax[2].set_title("NumPy engine run")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0, help="robot run, wall minutes")
    ap.add_argument("--steps", type=int, default=10**6, help="NumPy run, major steps")
    ap.add_argument("--robots", type=int, default=20)
    ap.add_argument("--rate", type=float, default=50.0, help="control and odometry rate [Hz]")
    ap.add_argument("--skip-robots", action="store_true")
    ap.add_argument("--json", help="write the figures here")
    ap.add_argument("--plot", default=str(Path(__file__).with_name("soak.png")))
    a = ap.parse_args(argv)
    results = []
    if not a.skip_robots and a.minutes > 0:
        results.append(robots_soak(a.minutes, a.robots, a.rate))
    if a.steps > 0:
        results.append(numpy_soak(a.steps, a.robots))
    print(table([v for v, _ in results]))
    if a.plot:
        plot(results, a.plot)
        print(f"\nwrote {a.plot}")
    if a.json:
        Path(a.json).write_text(json.dumps(
            [{**v, "series": {k: np.asarray(x).tolist() if np.ndim(x) else x
                              for k, x in s.items()}} for v, s in results],
            default=float, indent=1))
    return 0 if all(v["rss_flat"] and v["results_complete"] and v.get("no_miss_growth", True)
                    for v, _ in results) else 1


if __name__ == "__main__":
    sys.exit(main())
