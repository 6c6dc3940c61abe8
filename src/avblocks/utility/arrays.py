"""Small array helpers for block code that must run under NumPy and JAX."""

from __future__ import annotations

import numpy as np


def columns(xp, *cols):
    """Stack 1-D arrays of equal length as the columns of an (N, k) array.

    Same result as ``xp.stack(cols, axis=-1)``; under NumPy it fills a new
    array column by column, which costs a third of ``np.stack`` for the small
    arrays of few-agent runs. (The new array is the function's own: nothing
    handed in is written.)

    >>> columns(np, np.array([1.0, 2.0]), np.array([3.0, 4.0]))
    array([[1., 3.],
           [2., 4.]])
    """
    if xp is np:
        n = np.shape(cols[0])[0]
        out = np.empty((n, len(cols)), dtype=np.result_type(*cols))
        for j, c in enumerate(cols):
            out[:, j] = c
        return out
    return xp.stack(cols, axis=-1)


#: Axes up to this length are reduced by :func:`fold`'s fused form.
FOLD_MAX = 32


def fold(op, x, axis, xp):
    """Reduce ``x`` along ``axis`` with the elementwise binary ``op``
    (``xp.minimum``, ``xp.maximum``, ``xp.add``), the axis removed.

    Under JAX a short axis (``<= FOLD_MAX``) is reduced by ``lax.reduce``
    with the operation written as a ``where`` (``add`` as ``a - (-b)``,
    the same number), which XLA's CPU backend fuses with what produced
    ``x``; the plain ``min``/``max``/``sum`` reductions it hands to a
    library kernel (YNNPACK), slow for rows of a few elements (an agent's
    obstacles or neighbours) on XLA's default threads (the navigation
    rollout at 1024 copies: 62 ms against 82 ms with the plain reductions,
    best of 15 alternated runs; alike on one thread). NumPy
    and long axes: ``xp.min`` etc."""
    axis = axis % x.ndim
    m = x.shape[axis]
    red = {id(xp.minimum): "min", id(xp.maximum): "max", id(xp.add): "sum"}[id(op)]
    if xp is np or m > FOLD_MAX or m == 0:
        return getattr(xp, red)(x, axis=axis)
    from jax import lax
    if red == "sum":                            # a - (-b): exactly a + b
        return lax.reduce(x, xp.asarray(0, x.dtype), lambda a, b: a - (-b), (axis,))
    if not xp.issubdtype(x.dtype, xp.floating):
        init = xp.iinfo(x.dtype).max if red == "min" else xp.iinfo(x.dtype).min
        pick = (lambda a, b: xp.where(a < b, a, b)) if red == "min" else \
            (lambda a, b: xp.where(a > b, a, b))
    else:
        # a NaN wins, as in xp.min / xp.max (a NaN is never silently dropped)
        init = xp.inf if red == "min" else -xp.inf
        pick = (lambda a, b: xp.where((a < b) | (a != a), a, b)) if red == "min" else \
            (lambda a, b: xp.where((a > b) | (a != a), a, b))
    return lax.reduce(x, xp.asarray(init, x.dtype), pick, (axis,))


def norm2(v):
    """Squared length of 2-vectors ``v`` (..., 2): ``v_x^2 + v_y^2`` (no
    reduce over the short last axis: see :func:`fold`)."""
    return v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]


def map_rows(fn, arrays, xp, size):
    """``fn(*arrays)`` over blocks of ``size`` rows (all ``arrays`` share
    their leading length Q), the outputs (a tuple of arrays) joined along
    their first axis: a Python loop of blocks under NumPy, ``lax.map`` when
    traced (one compiled body; the last block is padded by repeating the
    last row, and the padding is cut off). One block when ``size`` is None
    or Q fits it."""
    qn = arrays[0].shape[0]
    if size is None or qn <= size:
        return fn(*arrays)
    if xp is np:
        outs = [fn(*[x[i:i + size] for x in arrays]) for i in range(0, qn, size)]
        return tuple(np.concatenate(parts, axis=0) for parts in zip(*outs))
    import jax
    m = -(-qn // size)
    pad = m * size - qn

    def blocks(x):
        if pad:
            x = xp.concatenate([x, xp.broadcast_to(x[-1:], (pad,) + x.shape[1:])], 0)
        return x.reshape((m, size) + x.shape[1:])

    outs = jax.lax.map(lambda xs: fn(*xs), [blocks(x) for x in arrays])
    return tuple(o.reshape((m * size,) + o.shape[2:])[:qn] for o in outs)


def batched(arrays):
    """True while the compiled engine traces a ``vmap``ped run (an
    ensemble; :func:`avblocks.core.diagnostics.vmapped`) or when a value
    is batched where it is traced (``vmap`` of a step, as the
    reinforcement-learning environments do). There a conditional on a
    batched value runs every branch (a traced spatial search then keeps its
    plan's one width) and the runs already divide the work. Inside a
    ``lax.scan`` under a ``vmap`` the engine does not know of, a batched
    value looks like any other: every branch runs (the same results, more
    work)."""
    from ..core import diagnostics
    if diagnostics.is_vmapped():
        return True
    try:
        from jax._src.interpreters.batching import BatchTracer
    except ImportError:             # pragma: no cover - another JAX layout
        return False
    return any(isinstance(a, BatchTracer) for a in arrays)


#: A traced per-agent law whose (N, K) tables of one float are larger than
#: this is evaluated in blocks of rows on a CPU (:func:`cache_rows`): each
#: of its elementwise passes then stays in the core's cache instead of
#: streaming the whole table through memory once per pass.
CACHE_TABLE_BYTES = 4 * 2 ** 20

#: Bytes of one (rows, K) table of a block of :func:`cache_rows`.
CACHE_BLOCK_BYTES = 384 * 1024


def cache_rows(n, width, dtype, xp, batched=False):
    """Rows per block for a traced per-row law over (``n``, ``width``)
    tables of ``dtype`` floats, or None (the whole table in one pass).

    Blocks of about :data:`CACHE_BLOCK_BYTES` per table on a CPU when the
    table exceeds :data:`CACHE_TABLE_BYTES`. None under NumPy, under
    ``vmap`` (``batched``: the runs already split the work) and on an
    accelerator, where one wide pass is what the device is made for.

    Measured on the flocking law (Olfati-Saber, K = 12, four evaluations as
    in an RK4 step, XLA on a 2-core CPU with 1 MiB of L2 per core): N =
    10^5, one pass 95.5 ms, blocks of 4096 rows 54-64 ms (1024 rows: 103;
    8192: 59; 16384: 77); N = 10^6 866 -> 563 ms; N = 3 x 10^4 20.5 ->
    18.8 ms; N = 10^4 (a 0.9 MiB table) 5.0 ms in one pass, 7.7 in blocks."""
    if xp is np or batched:
        return None
    import jax
    if jax.default_backend() != "cpu":
        return None
    width = max(1, int(width))
    item = np.dtype(dtype).itemsize
    if n * width * item <= CACHE_TABLE_BYTES:
        return None
    rows = CACHE_BLOCK_BYTES // (width * item)
    return 1 << max(0, int(rows).bit_length() - 1)
