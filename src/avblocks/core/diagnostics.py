"""What a traced run must check after it ends (static-capacity overflows).

Blocks whose shapes are fixed by a plan (a neighbour search's capacity,
hits and reach, see :mod:`avblocks.utility.spatial`) hand what each
evaluation *needed* to :func:`report`. Outside the compiled engine
:func:`report` does nothing (NumPy searches size themselves).

While the compiled engine traces a block's function it names the block
(:func:`block`); :func:`report` then adds to the trace a test ``need >
plan`` and, only where it holds, a host callback (``jax.debug.callback``)
that records the need. A run that never overflows pays for one comparison
per search call and never calls back. After a run the engine reads what
was recorded (:func:`recorded`) and decides (see
:mod:`avblocks.core.compiled.plans`): re-plan, recompile once and rerun, or
raise. Records are keyed by ``(block name, search number)`` (the order of
the block's ``searches()``), so programs shared by diagrams of the same
structure record under the same keys. Records are process-wide: runs of
the same diagram in several threads at once share them.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import threading

import numpy as np

_CURRENT: contextvars.ContextVar = contextvars.ContextVar("avblocks_block", default=None)
_LOCK = threading.Lock()
#: {(block name, search number): array [capacity, hits, reach, span]} running maxima
_RECORDS: dict = {}


@contextlib.contextmanager
def block(name, obj):
    """The compiled engine is tracing a function of block ``obj`` named ``name``."""
    tok = _CURRENT.set((name, obj))
    try:
        yield
    finally:
        _CURRENT.reset(tok)


@contextlib.contextmanager
def unreported():
    """Trace without overflow reports: :func:`report` does nothing inside
    (for code that ``vmap``-s single steps, where each report would call
    the host at every step; its searches must then be exact or planned
    with headroom)."""
    tok = _CURRENT.set(None)
    try:
        yield
    finally:
        _CURRENT.reset(tok)


def searches_of(b):
    """The neighbour searches block ``b`` owns: ``b.searches()`` when it has
    that method, else every attribute that is a
    :class:`~avblocks.utility.spatial.NeighborSearch` (recognised by its
    class attribute ``neighbor_search = True``; core does not import
    utility)."""
    m = getattr(b, "searches", None)
    if callable(m):
        return list(m())
    return [v for _, v in sorted(vars(b).items())
            if getattr(type(v), "neighbor_search", False)]


def _record(key, vec):
    v = np.asarray(vec, dtype=float).reshape(-1, 4).max(axis=0)
    with _LOCK:
        old = _RECORDS.get(key)
        _RECORDS[key] = v if old is None else np.maximum(old, v)


def report(owner, need, plan):
    """Record that ``owner`` (a search object) needed ``need`` under ``plan``."""
    cur = _CURRENT.get()
    if cur is None or plan is None:
        return
    name, b = cur
    num = next((j for j, s in enumerate(searches_of(b)) if s is owner), None)
    if num is None:
        return
    import jax
    import jax.numpy as jnp
    vec = jnp.stack([jnp.asarray(need.capacity).astype(float).reshape(()),
                     jnp.asarray(need.hits).astype(float).reshape(()),
                     jnp.max(jnp.asarray(need.reach)).astype(float).reshape(()),
                     jnp.asarray(getattr(need, "span", 0.0)).astype(float).reshape(())])
    inf = float("inf")
    cap = inf if (plan.capacity is None or plan.brute) else float(plan.capacity)
    hits = inf if plan.hits is None else float(plan.hits)
    # a radius rounded to float32 (relative 6e-8) is not an overflow
    limit = jnp.asarray([cap, hits, plan.reach * (1 + 1e-6), 1.0], dtype=vec.dtype)
    over = jnp.any(vec > limit)
    rec = functools.partial(_record, (name, num))
    jax.lax.cond(over, lambda v: jax.debug.callback(rec, v), lambda v: None, vec)


def clear():
    """Forget every record (the compiled engine calls it before a run)."""
    with _LOCK:
        _RECORDS.clear()


def recorded():
    """``{(block name, search number): (capacity, hits, reach, span)}`` needed
    beyond the plans since :func:`clear`."""
    with _LOCK:
        return {k: tuple(v) for k, v in _RECORDS.items()}
