"""What a traced run must check after it ends (static-capacity overflows).

Blocks whose shapes are fixed by a plan (a neighbour search's capacity,
hits and reach, see :mod:`avblocks.utility.spatial`) hand what each
evaluation *needed* to :func:`report`. Outside the compiled engine
:func:`report` does nothing (NumPy searches size themselves).

While the compiled engine traces a block's function it names the block
(:func:`block`), and while it traces a step it keeps a *tally*
(:func:`tally`): one row ``[capacity, hits, reach, span]`` per search of
the diagram, a traced array. :func:`report` takes the running maximum of
the row of the search that reported. The engine carries the tally through
its scans (the carry holds it), returns it with the run's results and
compares it with the plans once, after the run (see
:mod:`avblocks.core.compiled.plans`): re-plan, recompile once and rerun, or
raise. Nothing calls back to the host during a run, so a run costs the same
under ``vmap`` (ensembles, vectorised environments) as alone. Rows are
keyed by ``(block name, search number)`` (the order of the block's
``searches()``), so programs shared by diagrams of the same structure keep
the same rows.

A block that calls a search inside its own ``lax.cond``/``while_loop``
body carries the tally through it as well: :func:`held` before, the body
traced under :func:`resumed`, :func:`absorb` of what comes out (the
Verlet list rebuild of :mod:`avblocks.utility.spatial.verlet` does).
The reinforcement-learning environments, which step the engine
themselves, keep a tally the same way: it rides in their state from step
to step and is checked on the host after resets, steps and rollouts
(:meth:`avblocks.rl.FunctionalEnv.check`). Code that traces blocks without
any tally (a block's function jitted alone) gets no reports and no cost; a
search that would cut its selection short to a plan is exact there
(:func:`kept`), so no caller needs a special case.
"""

from __future__ import annotations

import contextlib
import contextvars

_CURRENT: contextvars.ContextVar = contextvars.ContextVar("avblocks_block", default=None)
_TALLY: contextvars.ContextVar = contextvars.ContextVar("avblocks_tally", default=None)


@contextlib.contextmanager
def block(name, obj):
    """The compiled engine is tracing a function of block ``obj`` named ``name``."""
    tok = _CURRENT.set((name, obj))
    try:
        yield
    finally:
        _CURRENT.reset(tok)


_VMAPPED: contextvars.ContextVar = contextvars.ContextVar("avblocks_vmapped", default=False)


@contextlib.contextmanager
def vmapped():
    """The compiled engine is tracing a ``vmap``ped run (an ensemble): code
    that would branch on a value (``lax.switch``) takes one branch for all
    runs instead (under ``vmap`` a branch on a batched value runs them all)."""
    tok = _VMAPPED.set(True)
    try:
        yield
    finally:
        _VMAPPED.reset(tok)


def is_vmapped() -> bool:
    """True inside :func:`vmapped`."""
    return _VMAPPED.get()


_SHARDED: contextvars.ContextVar = contextvars.ContextVar("avblocks_sharded", default=None)


@contextlib.contextmanager
def sharded(mesh, axis):
    """The compiled engine is tracing a run whose agents are split over the
    devices of ``mesh`` along its axis ``axis`` (``compile(...,
    shard="agents")``): a neighbour search answers each device's share of
    the queries on that device (:mod:`avblocks.utility.spatial.queries`)."""
    tok = _SHARDED.set((mesh, axis))
    try:
        yield
    finally:
        _SHARDED.reset(tok)


def sharding():
    """``(mesh, axis)`` inside :func:`sharded`, else None."""
    return _SHARDED.get()


class Tally:
    """The needs reported while one traced body runs: ``rows`` maps
    ``(block name, search number)`` to a row of ``value`` (a traced
    ``(len(rows), 4)`` array of running maxima)."""

    __slots__ = ("rows", "value")

    def __init__(self, rows, value):
        self.rows = rows
        self.value = value


@contextlib.contextmanager
def tally(rows, value):
    """Reports made inside go to a new :class:`Tally` (yielded) with these
    rows, starting from ``value``; read its ``value`` afterwards."""
    tok = _TALLY.set(Tally(rows, value) if rows else None)
    try:
        yield _TALLY.get()
    finally:
        _TALLY.reset(tok)


def held():
    """The current tally's value (to carry into a control-flow body), or
    None when no tally is kept."""
    t = _TALLY.get()
    return None if t is None else t.value


@contextlib.contextmanager
def resumed(value):
    """Inside a control-flow body: a tally with the current one's rows
    starting from ``value`` (what :func:`held` gave, carried in); yields it
    (None when no tally is kept)."""
    outer = _TALLY.get()
    if outer is None or value is None:
        yield None
        return
    with tally(outer.rows, value) as t:
        yield t


def through(fn):
    """``fn`` as a control-flow body that carries the tally: ``(x, needs) ->
    (fn(x), needs')``, where ``needs`` is what :func:`held` gave and the
    searches ``fn`` traces report to a tally resumed from it (pass
    ``needs'`` out of the control flow to :func:`absorb`)."""
    def body(op):
        x, needs = op
        with resumed(needs) as tl:
            y = fn(x)
        return y, (needs if tl is None else tl.value)
    return body


def absorb(value):
    """After a control-flow body: its tally's value (which started from
    :func:`held`) becomes the current tally's."""
    t = _TALLY.get()
    if t is not None and value is not None:
        t.value = value


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


def _row(owner):
    """The current tally and ``owner``'s row in it, or ``(None, None)``."""
    cur = _CURRENT.get()
    t = _TALLY.get()
    if cur is None or t is None:
        return None, None
    name, b = cur
    num = next((j for j, s in enumerate(searches_of(b)) if s is owner), None)
    row = t.rows.get((name, num))
    return (None, None) if row is None else (t, row)


def kept(owner) -> bool:
    """Whether a :func:`report` of ``owner`` (a search object) now reaches a
    tally that the engine checks after the run. A search that may cut a
    selection short to its plan must be exact where this is False (an
    environment stepping the engine itself keeps no tally)."""
    return _row(owner)[0] is not None


def report(owner, need, plan):
    """Record that ``owner`` (a search object) needed ``need`` under ``plan``
    (a running maximum in the current tally; nothing without one)."""
    if plan is None:
        return
    t, row = _row(owner)
    if t is None:
        return
    import jax
    import jax.numpy as jnp
    dt = t.value.dtype
    vec = jnp.stack([jnp.asarray(need.capacity).astype(dt).reshape(()),
                     jnp.asarray(need.hits).astype(dt).reshape(()),
                     jnp.max(jnp.asarray(need.reach)).astype(dt).reshape(()),
                     jnp.asarray(getattr(need, "span", 0.0)).astype(dt).reshape(())])
    t.value = t.value.at[row].max(jax.lax.stop_gradient(vec))


def rows_of(blocks, names):
    """``{(block name, search number): row}`` of every search the blocks own."""
    keys = [(n, j) for n, b in zip(names, blocks) for j, _ in enumerate(searches_of(b))]
    return {k: r for r, k in enumerate(keys)}
