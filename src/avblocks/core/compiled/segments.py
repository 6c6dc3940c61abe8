"""A compiled run in segments: progress reports and a stop between them.

One compiled run is one call of one program (a ``lax.scan`` over the whole
run): nothing comes back to Python until it ends. A run given
``progress`` (``simulate(..., backend="jax", progress=cb)``, or
``runner(progress=cb)``) is driven in segments instead: the same program's
outer loop (one iteration per log sample) cut into pieces of
:func:`segment_length` samples, each piece one call of one compiled segment
(:meth:`~avblocks.core.compiled.program.Program.segment`) that takes the
carried state of the last one and the index it starts at as arguments. So

* one segment program serves every segment of every run of the structure
  (the start index is data: no compile per segment, none per run);
* the values are those of the whole scan, bit for bit (the segment is
  traced from the same body; tested);
* between segments ``progress(step, steps)`` is called with the steps done,
  as the NumPy engine calls it (not again for a last segment that only
  logs the final sample); a ``KeyboardInterrupt`` raised there (or Ctrl-C) stops the run
  and the samples logged so far come back, marked as the NumPy engine marks
  them (``meta["interrupted"]``, ``"interrupted_at"``, ``"interrupted_by"``),
  with the state reached in ``final_state``.

The next segment is queued before the rows of the last one are read, so
the device runs segment after segment without waiting for Python; what a
segment costs is its dispatch and the copy of its log rows
(docs/compiled.md gives the figures measured on ``flocking``). A stop
drops the segment queued after the last one reported.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..errors import ParameterError
from . import _jax
from . import devices as _devices

#: most segments a run is cut into (a report every 2 % of the run)
SEGMENTS = 50

#: fewest major steps a segment runs (unless the run is shorter): a segment
#: costs a dispatch and a copy, about as much as a few steps of a small
#: diagram (docs/compiled.md), so short runs are cut into fewer pieces
MIN_STEPS = 50

#: wall seconds a segment should take at most: a stop (the editor's Cancel,
#: Ctrl-C) waits for the segment running, so a long run of a slow diagram is
#: cut into segments sized by the pace of its first one, not by SEGMENTS alone
SEGMENT_SECONDS = 0.1

#: most major steps the first segment runs: it measures the pace
FIRST_STEPS = 512


def paced_length(length: int, seconds: float, samples: int) -> int:
    """Samples per segment at the pace measured (``samples`` took
    ``seconds``): ``length`` when a segment of it takes at most
    :data:`SEGMENT_SECONDS`, else the largest power of two that does (one
    sample at least; powers of two, so that runs of one structure share a
    few compiled segment programs)."""
    per = seconds / max(1, int(samples))
    if per * length <= SEGMENT_SECONDS:
        return int(length)
    fit = max(1, int(SEGMENT_SECONDS / per)) if per > 0 else int(length)
    return max(1, min(int(length), 1 << (fit.bit_length() - 1)))


def segment_length(nlog: int, log_every: int = 1) -> int:
    """Log samples (outer iterations) per segment: the run's ``nlog``
    samples cut into at most :data:`SEGMENTS` equal pieces of at least
    :data:`MIN_STEPS` steps (``log_every`` steps per sample), one sample
    at least."""
    by_count = -(-int(nlog) // max(1, int(SEGMENTS)))
    by_steps = -(-int(MIN_STEPS) // max(1, int(log_every)))
    return max(1, min(int(nlog), max(by_count, by_steps)))


def reporter(progress):
    """What a ``progress`` argument asks for: a callable (called between
    segments), ``True`` (a bar), or None for ``None`` and ``False`` (the
    whole run in one call); anything else raises :class:`ParameterError`."""
    if progress is None or (isinstance(progress, (bool, np.bool_)) and not progress):
        return None
    if callable(progress) or isinstance(progress, (bool, np.bool_)):
        return progress if callable(progress) else True
    raise ParameterError("progress must be None, True, False or a callable "
                         "progress(step, steps)", param="progress",
                         found=repr(progress)[:40])


def run(runner, theta, X0, seed, params, progress):
    """One run of ``runner`` in segments (see the module docstring);
    ``progress`` is a callable ``progress(step, steps)`` or ``True`` (a bar).
    Returns ``(Results, needs, stopped)``: ``needs`` the neighbour
    searches' tally over the steps run, ``stopped`` whether a
    ``KeyboardInterrupt`` ended it early."""
    from ..runguard import progress_bar
    jax = _jax.jax()
    prog = runner.program
    nlog, le, nsteps = prog.nlog, prog.log_every, prog.nsteps
    length = segment_length(nlog, le)
    bar = progress_bar(nsteps) if progress is True else None
    report = None if progress is True else progress

    first = min(length, max(1, FIRST_STEPS // max(1, le)))

    def build(n):
        return lambda: (lambda theta, carry, i0: prog.segment(theta, carry, i0, n))

    i0 = np.asarray(0, np.int32)
    carry = prog.segment_start(X0)
    exe, compile_s, place, args = runner._placed(("segment", first), build(first),
                                                 runner._single, (theta, carry, i0))
    theta_p = args[0]
    exes = {first: exe}

    def segment_of(n):
        """The compiled segment of ``n`` samples (compiled once per length)."""
        nonlocal compile_s
        if n not in exes:
            exes[n], more, _place, _args = runner._placed(
                ("segment", n), build(n), runner._single, (theta, carry, i0))
            compile_s += more
        return exes[n]

    bufs = [np.empty((nlog, *s.shape), dtype=s.dtype) for s in runner.specs]
    count, done, segments = 0, 0, 0
    interrupt = None
    t = time.perf_counter()
    try:
        with _jax.x64(prog.x64):
            carry = args[1]
            # (start, samples, result): the segment running; the next is queued
            # before this one's rows are read, so the device never waits for
            # Python (dropped unread if the run is stopped here); the first is
            # read before the next is sent, to size the others by its pace
            running = (0, first, exe(theta_p, carry, args[2]))
            n = first
            while running is not None:
                start, size, (new, rows) = running
                nxt = start + size
                running = None
                if segments > 0 and nxt < nlog:
                    running = (nxt, n, segment_of(n)(theta_p, place(new),
                                                     place(np.asarray(nxt, np.int32))))
                take = min(size, nlog - start)
                for b, r in zip(bufs, rows):
                    b[count:count + take] = _devices.host(r)[:take]
                if segments == 0:
                    n = paced_length(length, time.perf_counter() - t, size)
                    if nxt < nlog:
                        running = (nxt, n, segment_of(n)(theta_p, place(new),
                                                         place(np.asarray(nxt, np.int32))))
                was = done
                carry, count, done = new, count + take, (
                    nsteps if nxt >= nlog else nxt * le)
                segments += 1
                if bar is not None:
                    bar.update(done - was)
                if report is not None and done > was:
                    report(done, nsteps)
    except KeyboardInterrupt as e:
        interrupt = e
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t
    X, needs = carry[0], carry[2]
    flat, tree = jax.tree_util.tree_flatten(X)
    XF = jax.tree_util.tree_unflatten(tree, [_devices.host(a) for a in flat])
    meta = runner._meta(seed, params, wall, compile_s)
    meta["segments"] = segments
    if interrupt is not None:
        # as the NumPy engine marks a stopped run (core.run_loop)
        meta.pop("realtime_factor", None)
        meta["interrupted"] = True
        meta["interrupted_at"] = prog.t0 + done * prog.dt
        meta["interrupted_by"] = getattr(interrupt, "signal_name", "SIGINT")
    else:
        meta["realtime_factor"] = (nsteps * prog.dt / wall) if wall > 0 else math.inf
    logs = bufs if count == nlog else [b[:count].copy() for b in bufs]
    res = runner._results(logs, XF, meta, t=runner.t[:count].copy())
    if needs is None:
        needs = np.zeros((0, 4))
    return res, needs, interrupt is not None
