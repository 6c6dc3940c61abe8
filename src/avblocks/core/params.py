"""Parameter validation, done once when a block is constructed.

Each helper turns what a user passed (a scalar, a list, an array) into an
array of the expected shape, or raises :class:`ParameterError` naming the
block, the parameter, what was expected and what was found.
"""

from __future__ import annotations

import numpy as np

from .errors import ParameterError


def _as_float(value, block, name):
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError("must be numeric", block=block, param=name,
                             expected="a number or array of numbers",
                             found=repr(value)[:80]) from None
    return a


def finite_array(value, block, name, shape=None, *, allow_nan=False,
                 allow_inf=False):
    """A float array of exactly ``shape`` (``None``: any), all finite
    (``allow_inf``: +-inf accepted, e.g. one-sided bounds; NaN never unless
    ``allow_nan``)."""
    a = _as_float(value, block, name)
    if shape is not None and a.shape != tuple(shape):
        raise ParameterError("wrong shape", block=block, param=name,
                             expected=tuple(shape), found=a.shape)
    if not allow_nan and np.any(np.isnan(a)):
        raise ParameterError("must not be NaN", block=block, param=name, found=a)
    if not allow_inf and not allow_nan and not np.all(np.isfinite(a)):
        raise ParameterError("must be finite (no NaN or inf)", block=block,
                             param=name, found=a)
    return a


def agent_array(value, n, block, name, comp=(), *, positive=False,
                nonnegative=False, allow_inf=False):
    """Broadcast a scalar, a per-agent vector or a full array to ``(n, *comp)``.

    ``value`` may be a scalar (same for all agents), an array of shape
    ``comp`` (same for all agents), of shape ``(n,)`` when ``comp`` is empty,
    or of shape ``(n, *comp)`` (one per agent).
    """
    a = _as_float(value, block, name)
    full = (n, *comp)
    if a.shape in ((), tuple(comp), full):
        a = np.broadcast_to(a, full).copy()
    else:
        raise ParameterError("wrong shape", block=block, param=name,
                             expected=f"a scalar, {tuple(comp) or '()'} or {full}",
                             found=a.shape)
    if np.any(np.isnan(a)) or (not allow_inf and not np.all(np.isfinite(a))):
        raise ParameterError("must be finite (no NaN or inf)" if not allow_inf else
                             "must not be NaN", block=block, param=name, found=a)
    if positive and not np.all(a > 0):
        raise ParameterError("must be > 0", block=block, param=name,
                             expected="> 0", found=a.min())
    if nonnegative and not np.all(a >= 0):
        raise ParameterError("must be >= 0", block=block, param=name,
                             expected=">= 0", found=a.min())
    return a


def limit(value, n, block, name, comp=()):
    """A per-agent limit broadcast to ``(n, *comp)``: ``>= 0``, ``inf`` for none."""
    return agent_array(value, n, block, name, comp, nonnegative=True, allow_inf=True)


def positive_scalar(value, block, name, *, allow_zero=False, allow_inf=False):
    """A single positive float."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError("must be a number", block=block, param=name,
                             expected="a number", found=repr(value)[:80]) from None
    ok = (v >= 0 if allow_zero else v > 0) and (allow_inf or np.isfinite(v))
    if not ok or np.isnan(v):
        raise ParameterError("out of range", block=block, param=name,
                             expected=">= 0" if allow_zero else "> 0", found=v)
    return v


def poses(value, block, name="pose0", dim=3):
    """An ``(N, dim)`` float array of initial poses/positions, N >= 1."""
    a = _as_float(value, block, name)
    if a.ndim == 1 and a.shape == (dim,):
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != dim or a.shape[0] < 1:
        raise ParameterError("wrong shape", block=block, param=name,
                             expected=f"(N, {dim}) with N >= 1", found=a.shape)
    if not np.all(np.isfinite(a)):
        raise ParameterError("must be finite (no NaN or inf)", block=block,
                             param=name, found="non-finite entries")
    return a
