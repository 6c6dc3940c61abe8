"""Benchmark: render N agents with trails to an MP4 movie.

Run: ``python benchmarks/viz.py [--agents 500] [--frames 300]``. Prints a
markdown table (render + encode wall time). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

import avblocks as av  # noqa: E402
import avblocks.viz as viz  # noqa: E402


def make_results(n, frames, dt=0.05, seed=0):
    """Unicycles on constant random commands, simulated by avblocks."""
    rng = np.random.default_rng(seed)
    pose0 = np.c_[rng.uniform(-50, 50, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    cmd = np.c_[rng.uniform(0.5, 2.0, n), rng.uniform(-0.5, 0.5, n)]
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
    c = d.add(av.blocks.Constant(cmd), name="c")
    d.connect(c.y, f.cmd)
    return av.simulate(d, (frames - 1) * dt, dt=dt, log=[f.pose])


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--agents", type=int, default=500)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--trail", type=float, default=2.0, help="trail length [s]")
    args = ap.parse_args()
    res = make_results(args.agents, args.frames)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for drawing in ("arrow", "car"):
            path = os.path.join(tmp, f"{drawing}.mp4")
            t0 = time.perf_counter()
            viz.save_movie(res, path, fps=30, trail=args.trail, drawing=drawing,
                           progress=False)
            wall = time.perf_counter() - t0
            frames, _ = viz.read_video(path)
            rows.append((drawing, len(frames), frames.shape[2], frames.shape[1], wall,
                         os.path.getsize(path) / 2**20))
    print(f"\n{args.agents} agents, trails {args.trail} s, {os.cpu_count()} cores\n")
    print("| drawing | frames | size | wall [s] | frames/s | file [MB] |")
    print("|---|---|---|---|---|---|")
    for d, nf, w, h, wall, mb in rows:
        print(f"| {d} | {nf} | {w}x{h} | {wall:.1f} | {nf / wall:.1f} | {mb:.2f} |")


if __name__ == "__main__":
    main()
