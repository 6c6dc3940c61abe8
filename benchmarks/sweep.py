"""Sweeps of the waypoints scenario: a serial loop vs a Dask LocalCluster vs
(where available) one vmapped JAX ensemble; wall time and the client's peak
memory.

    python benchmarks/sweep.py                 # the 64-case table + memory table
    python benchmarks/sweep.py --quick         # smaller

Each measurement runs in a fresh Python process so its peak RSS
(``resource.getrusage``) belongs to that mode alone. Modes:

- ``serial``: a loop in one process keeping only the metrics;
- ``serial-keep``: the usual hand-written loop that keeps every Results
  (what makes batch runners run out of memory);
- ``dask``: ``av.sweep`` on a LocalCluster of 2 worker processes, each case's
  metrics and decimated pose log written by the workers to the Zarr store;
- ``jax``: in this one process, the seeds of each grid point as one vmapped
  ensemble (``avblocks.compile(...).ensemble``, float64, CPU), 4 ensembles;
- ``dask-ensemble``: ``av.sweep(..., ensemble=True)`` on 2 worker processes
  (one task per grid point).

The client's figure includes the Dask scheduler, which a LocalCluster runs
inside the client process.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

SPEEDS = [1.0, 1.5, 2.0, 2.5]


def _cases(n_cases):
    seeds = max(1, n_cases // len(SPEEDS))
    return {"speed": SPEEDS}, seeds


def run_one(mode, n_cases, t_final, agents, workdir):
    import avblocks as av
    grid, seeds = _cases(n_cases)
    fixed = {"agents": agents, "simulation.t_final": t_final}
    metrics = ["done_fraction", "time_to_done", "min_gap"]
    t0 = time.perf_counter()
    if mode in ("serial", "serial-keep"):
        from avblocks.cli import load_any
        from avblocks.sweep.metrics import METRICS
        kept, table = [], []
        for v in grid["speed"]:
            for s in range(seeds):
                d, sim, *_ = load_any("waypoints", {**fixed, "speed": v, "seed": s})
                res = av.simulate(d, progress=False, **{**sim, "seed": s})
                table.append([METRICS[m](res) for m in metrics])
                if mode == "serial-keep":
                    kept.append(res)
    elif mode == "dask":
        out = os.path.join(workdir, "bench.zarr")
        av.sweep("waypoints", grid=grid, seeds=seeds, metrics=metrics, out=out,
                 fixed=fixed, workers=2, log=["fleet.pose"], log_every=10,
                 progress=False, summary=False, plot=False)
    elif mode == "dask-ensemble":
        out = os.path.join(workdir, "bench.zarr")
        av.sweep("waypoints", grid=grid, seeds=seeds, metrics=metrics, out=out,
                 fixed=fixed, workers=2, ensemble=True, progress=False, summary=False,
                 plot=False)
    elif mode == "jax":
        if getattr(av, "compile", None) is None:
            return {"mode": mode, "cases": n_cases, "wall_s": None, "peak_mib": None,
                    "note": "avblocks.compile not available"}
        from avblocks.sweep import make_spec
        from avblocks.sweep.ensemble import compute_group
        from avblocks.sweep.runner import task_groups
        spec, _ = make_spec("waypoints", grid, seeds, metrics, fixed=fixed, ensemble=True)
        for group in task_groups(spec, range(spec.n_cases)):   # one per grid point
            out = compute_group(spec, group)
            bad = [v for v in out.values() if isinstance(v, BaseException)]
            if bad:
                raise bad[0]
    wall = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"mode": mode, "cases": len(SPEEDS) * seeds, "wall_s": round(wall, 2),
            "peak_mib": round(peak, 1)}


def measure(mode, n_cases, t_final, agents):
    work = tempfile.mkdtemp(prefix="avb-sweep-bench-")
    try:
        cmd = [sys.executable, __file__, "--one", mode, "--cases", str(n_cases),
               "--t-final", str(t_final), "--agents", str(agents), "--workdir", work]
        p = subprocess.run(cmd, capture_output=True, text=True, check=False)
        lines = [ln for ln in p.stdout.splitlines() if ln.startswith("{")]
        if p.returncode or not lines:
            return {"mode": mode, "cases": n_cases, "wall_s": None, "peak_mib": None,
                    "note": (p.stderr.strip().splitlines() or ["failed"])[-1]}
        return json.loads(lines[-1])
    finally:
        shutil.rmtree(work, ignore_errors=True)


def table(rows, title):
    print(f"\n{title}\n")
    print("| mode | cases | wall [s] | client peak RSS [MiB] | note |")
    print("|---|---:|---:|---:|---|")
    for r in rows:
        w = "n/a" if r["wall_s"] is None else f"{r['wall_s']:.1f}"
        m = "n/a" if r["peak_mib"] is None else f"{r['peak_mib']:.0f}"
        print(f"| {r['mode']} | {r['cases']} | {w} | {m} | {r.get('note', '')} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--one")
    ap.add_argument("--cases", type=int, default=64)
    ap.add_argument("--t-final", type=float, default=20.0, dest="t_final")
    ap.add_argument("--agents", type=int, default=10)
    ap.add_argument("--workdir")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    if a.one:
        print(json.dumps(run_one(a.one, a.cases, a.t_final, a.agents, a.workdir)))
        return
    n, tf = (16, 5.0) if a.quick else (a.cases, a.t_final)
    rows = [measure(m, n, tf, a.agents) for m in ("serial", "dask", "jax", "dask-ensemble")]
    table(rows, f"{n} cases of waypoints ({a.agents} agents, {tf:g} s at dt = 10 ms, "
                f"RK4), 2 worker processes")
    mem = []
    for m in ("serial-keep", "dask"):
        for n_mem in (16, 256):
            mem.append(measure(m, n_mem, 5.0, a.agents))
    table(mem, "client memory as the sweep grows (5 s per case, pose logged)")


if __name__ == "__main__":
    main()
