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
