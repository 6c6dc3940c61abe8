"""Python cost around the compiled executable at N = 10 (W1 with the
``scaling.py --percall`` settings): the bare executable (placed arguments,
one call, block), a ``Runner`` call and a second ``simulate(backend="jax")``,
alternating for 40 rounds; each round keeps the best of 5 calls. Prints the
medians over the rounds and the median per-round differences to the bare
executable (what the Python around it costs, hot).

    python benchmarks/percall_overhead.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import scaling as S  # noqa: E402

import avblocks as av  # noqa: E402
from avblocks.core.compiled import _jax  # noqa: E402


def main():
    jax = _jax.jax()
    d, fleet = S.diagram(10)
    kw = dict(dt=S.DT, solver="euler", log=[fleet.pose], log_every=100)
    runner = av.compile(d, S.STEPS * S.DT, **kw)

    def sim():
        return av.simulate(d, S.STEPS * S.DT, backend="jax", progress=False, **kw)

    sim()
    runner()
    place, exe = runner._run_exe
    theta, _ = runner._theta(None)
    with _jax.x64(True):
        args = place((theta, runner._states({}, [0])))

    def bare():
        with _jax.x64(True):
            jax.block_until_ready(exe(*args))

    cases = {"executable": bare, "Runner call": runner, "simulate": sim}
    best = {k: [] for k in cases}
    for _ in range(40):
        for k, f in cases.items():
            m = float("inf")
            for _ in range(5):
                t = time.perf_counter()
                f()
                m = min(m, time.perf_counter() - t)
            best[k].append(m)
    for k, v in best.items():
        extra = ""
        if k != "executable":
            diff = statistics.median(a - b for a, b in zip(v, best["executable"]))
            extra = f"  (+{diff * 1e6:.0f} us over the executable)"
        print(f"{k:12s} {statistics.median(v) * 1e3:.3f} ms{extra}")


if __name__ == "__main__":
    main()
