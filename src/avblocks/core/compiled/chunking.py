"""How many runs of an ensemble go into one vmapped call (a chunk).

:meth:`Runner.ensemble <avblocks.core.compiled.runner.Runner.ensemble>`
splits its runs into chunks of equal size (the last one padded), all run by
one compiled program. The size is the smallest of

* the log budget: ``max_log_bytes // (log bytes of one run)``;
* on a CPU, a working set that stays in the core's cache: every device
  gets ``max(1, CPU_STEP_BYTES // step_bytes)`` runs, where ``step_bytes``
  is the largest array one step of one run computes
  (:func:`largest_step_array` of the traced run; the (N, N) distances of a
  dense neighbour search, an (N, K) neighbour table...), when that array
  is at least ``CPU_MIN_ARRAY`` (smaller ones leave the chunks big: their
  programs pay mostly a fixed cost per operation, shared by the runs of a
  chunk);
* the number of runs;

rounded down to whole runs per device (at least one each), then evened
out over the chunks it takes (the last chunk is padded: 32 runs under a
limit of 28 are 2 chunks of 16). A GPU keeps the big chunks of the log
budget: its many cores want work, not a small cache.
The platform is read from the devices (``device.platform``), never assumed.

Measured on this 2-core CPU (2 XLA devices; shared machine; median of
alternating calls, docs/benchmarks.md): the ``flocking`` ensemble (50
agents, a dense search: 20 kB per step array) ran 64 runs in one chunk in
1.18 s and in chunks of 8 (4 runs per device) in 0.95 s; 256 runs of 100
unicycles (2.4 kB arrays) want chunks of 64 or more (0.57 s, chunks of 8
0.80 s), and so does ``swap`` (above): a fixed chunk size serves one of
them, the size of the step's arrays all.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError

#: bytes of step arrays (largest array of a step x runs) one CPU device
#: gets per chunk: a few times that is what a step touches, in L2
CPU_STEP_BYTES = 80 * 1024

#: the cache limit above applies from this largest step array on (a (45, 45)
#: float64 pairwise array); programs of smaller arrays pay mostly a fixed
#: cost per operation and step, which big chunks share out (the ``swap``
#: scenario, 20 agents, 5.7 kB arrays, 32 runs: 0.20 s in one chunk, 0.40 s
#: in 2, 0.77 s in 4)
CPU_MIN_ARRAY = 16 * 1024


def largest_step_array(jaxpr) -> int:
    """Bytes of the largest value computed inside the loops of a traced run
    (``jax.make_jaxpr`` of one run): the equations of every nested jaxpr
    (scan, while and cond bodies), not the top level, whose outputs are the
    stacked logs."""
    best = 0
    seen = set()

    def walk(jp, depth):
        nonlocal best
        if id(jp) in seen:
            return
        seen.add(id(jp))
        for eqn in jp.eqns:
            if depth:
                for v in eqn.outvars:
                    aval = getattr(v, "aval", None)
                    shape = getattr(aval, "shape", None)
                    if shape is None or not hasattr(aval, "dtype"):
                        continue
                    best = max(best, math.prod(shape) * np.dtype(aval.dtype).itemsize)
            for p in eqn.params.values():
                for sub in (p if isinstance(p, (list, tuple)) else (p,)):
                    inner = getattr(sub, "jaxpr", sub)
                    if hasattr(inner, "eqns"):
                        walk(inner, depth + 1)
    walk(getattr(jaxpr, "jaxpr", jaxpr), 0)
    return best


def chunk_size(runs, log_bytes, max_log_bytes, devices, step_bytes=None, chunk=None):
    """Runs per vmapped call (see the module docstring). ``chunk`` (an int)
    overrides the policy and is taken as given; ``step_bytes`` is called
    (no arguments) only on a CPU, for the bytes of the largest step array."""
    if chunk is not None:
        if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) \
                or chunk < 1:
            raise ParameterError("chunk must be a whole number of runs >= 1",
                                 param="chunk", expected="int >= 1", found=repr(chunk))
        return int(min(chunk, runs))
    size = int(max(1, min(runs, max_log_bytes // max(log_bytes, 1))))
    ndev = len(devices)
    if devices and devices[0].platform == "cpu" and step_bytes is not None:
        largest = int(step_bytes())
        if largest >= CPU_MIN_ARRAY:
            size = min(size, max(1, CPU_STEP_BYTES // largest) * ndev)
    if ndev > 1 and runs > 1:
        # whole runs per device: a multiple of the device count (the last
        # chunk is padded anyway)
        size = max(ndev, size // ndev * ndev)
    # as many chunks as that size needs, made equal: the last chunk is
    # padded to the chunk size, so 32 runs in chunks of at most 28 run as
    # 2 x 16, not 28 + 28 (measured 0.30 s against 0.19 s in one chunk,
    # ``nest``, 40 agents)
    n = -(-runs // size)
    even = -(-runs // n)
    if ndev > 1 and runs > 1:
        even = -(-even // ndev) * ndev          # still <= size, a multiple of ndev
    return min(size, even)
