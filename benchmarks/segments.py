"""What driving a compiled run in segments costs (progress reports and a
stop between segments; :mod:`avblocks.core.compiled.segments`).

The ``flocking`` scenario's diagram (50 agents, a neighbour search every
step, dt = 0.02 s, every 5th step logged), 20 s = 1000 steps, run by one
``Runner``: the whole scan in one call, in segments of the default policy
(:func:`~avblocks.core.compiled.segments.segment_length`) and in segments
of the other lengths listed, alternating for ``--rounds`` rounds. Prints
the median and the best wall time of each and their excess over the whole
scan, and checks that every way gives the whole scan's values bit for bit.
Compiles once per way (not timed).

    python benchmarks/segments.py [--agents 50] [--t-final 20] [--rounds 7]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

import avblocks as av
from avblocks.core.compiled import segments
from avblocks.scenarios.flocking import make_diagram


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=50)
    ap.add_argument("--t-final", type=float, default=20.0)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--lengths", default="1,5,20",
                    help="samples per segment to compare with the default policy "
                         "(comma-separated)")
    a = ap.parse_args()
    d, _settings = make_diagram(agents=a.agents)
    runner = av.compile(d, a.t_final, dt=0.02, log_every=5)
    prog = runner.program
    lengths = [None] + [int(c) for c in a.lengths.split(",")]
    calls = []

    def whole():
        return runner()

    def seg(n):
        def go():
            keep = segments.segment_length
            if n is not None:
                segments.segment_length = lambda nlog, le: n
            try:
                return runner(progress=lambda k, s: calls.append(k))
            finally:
                segments.segment_length = keep
        return go

    def name(n):
        n = segments.segment_length(prog.nlog, prog.log_every) if n is None else n
        return f"{-(-prog.nlog // n)} x {n * prog.log_every} steps"

    ways = {"whole scan": whole, **{name(n) + (" (default)" if n is None else ""): seg(n)
                                    for n in lengths}}
    ref = whole()
    for name, fn in ways.items():          # compile (and check) each way once
        got = fn()
        for k in ref.keys():
            assert np.array_equal(np.asarray(ref[k]), np.asarray(got[k])), (name, k)
    times = {name: [] for name in ways}
    for _ in range(a.rounds):
        for name, fn in ways.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    base = statistics.median(times["whole scan"])
    print(f"flocking, {a.agents} agents, {runner.program.nsteps} steps, "
          f"{runner.program.nlog} log samples; load {os.getloadavg()[0]:.2f}; "
          f"{a.rounds} alternating rounds")
    best = min(times["whole scan"])
    print(f"{'segments':>28} {'median s':>9} {'excess':>8} {'best s':>8} {'excess':>8}")
    for way, ts in times.items():
        m, b = statistics.median(ts), min(ts)
        print(f"{way:>28} {m:9.3f} {100 * (m / base - 1):+7.1f}% {b:8.3f} "
              f"{100 * (b / best - 1):+7.1f}%")


if __name__ == "__main__":
    main()
