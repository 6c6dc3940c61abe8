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
        a = np.array(value, dtype=float, order="C")
    except (TypeError, ValueError):
        raise ParameterError("must be numeric", block=block, param=name,
                             expected="a number or array of numbers",
                             found=repr(value)[:80]) from None
    return a


def frozen(a):
    """``a`` (an array that owns its data) made read-only and returned.

    A block's parameter values and declared initial states are frozen: a
    new value replaces the array (:meth:`Block.set_parameter`,
    :meth:`Block.set_initial`), it is never written in place. So an array's
    identity stands for its contents, which lets a compiled runner keep its
    copy on the device between calls (:mod:`avblocks.core.compiled.runner`)
    and :meth:`Block.param_flag` keep its verdicts."""
    a.flags.writeable = False
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


# ------------------------------------------------------ numeric parameters
class Param:
    """Specification of a block's numeric parameter (a value, not structure).

    Numeric parameters are the values a run may change without rebuilding
    the diagram: gains, limits, radii, waypoints. A block declares each one
    with :meth:`Block.declare_parameter`; it then reads it as ``self.<name>``
    inside ``output``/``derivative``/``update`` only (never caches anything
    derived from it in ``__init__``), so the same code runs with a NumPy
    array, a new value set between steps, or a traced JAX value handed to
    a compiled step as an argument.

    Attributes
    ----------
    name : str
    shape : tuple of int
        Fixed when declared; a new value must broadcast to it.
    bounds : (low, high)
        Inclusive; ``None`` for no bound.
    unit, doc : str
    """

    __slots__ = ("name", "shape", "bounds", "unit", "doc", "allow_inf")

    def __init__(self, name, shape, bounds=(None, None), unit="", doc="",
                 allow_inf=False):
        self.name = name
        self.shape = tuple(shape)
        self.bounds = (bounds[0], bounds[1])
        self.unit = unit
        self.doc = doc
        self.allow_inf = bool(allow_inf)

    def validate(self, value, block="?"):
        """``value`` as a float64 array of this shape, or ParameterError."""
        a = _as_float(value, block, self.name)
        if a.shape != self.shape:
            try:
                a = np.broadcast_to(a, self.shape).copy()
            except ValueError:
                raise ParameterError("wrong shape", block=block, param=self.name,
                                     expected=f"{self.shape} (or broadcastable to it)",
                                     found=a.shape) from None
        if np.any(np.isnan(a)):
            raise ParameterError("must not be NaN", block=block, param=self.name)
        if not self.allow_inf and not np.all(np.isfinite(a)):
            raise ParameterError("must be finite", block=block, param=self.name,
                                 found="inf")
        lo, hi = self.bounds
        if lo is not None and np.any(a < lo):
            raise ParameterError("below its lower bound", block=block, param=self.name,
                                 expected=f">= {lo}", found=float(a.min()))
        if hi is not None and np.any(a > hi):
            raise ParameterError("above its upper bound", block=block, param=self.name,
                                 expected=f"<= {hi}", found=float(a.max()))
        return frozen(a)

    def __repr__(self):
        b = "" if self.bounds == (None, None) else f", bounds={self.bounds}"
        return f"Param({self.name!r}, shape={self.shape}{b})"


class bound_parameters:
    """Context manager: temporarily give blocks other parameter values.

    ``values`` is ``[(block, {name: value})]``. Used by the compiled backend
    to hand traced values to blocks for the duration of a trace, and by
    :func:`simulate` for ``params=``; the old values are restored on exit.
    No validation here (traced values cannot be checked): validate first.
    """

    def __init__(self, values):
        self.values = values
        self.saved = []

    def __enter__(self):
        for blk, vals in self.values:
            for k, v in vals.items():
                self.saved.append((blk, k, blk.__dict__[k]))
                blk.__dict__[k] = v
        return self

    def __exit__(self, *exc):
        for blk, k, v in reversed(self.saved):
            blk.__dict__[k] = v
        self.saved = []
        return False


def integer(value, block, name, *, lo=None, hi=None):
    """A Python int from an int-like value (``3``, ``3.0``, ``np.int64(3)``;
    never ``3.5``, ``"3"``, ``True``, NaN or inf), within ``[lo, hi]``."""
    bad = isinstance(value, (bool, np.bool_, str, bytes))
    v = None
    if not bad:
        try:
            f = value if isinstance(value, (int, np.integer)) else float(value)
            if isinstance(f, float) and not (np.isfinite(f) and f == int(f)):
                bad = True
            else:
                v = int(f)
        except (TypeError, ValueError, OverflowError):
            bad = True
    if bad:
        raise ParameterError("must be a whole number", block=block, param=name,
                             expected="an integer", found=repr(value)[:80])
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = (f">= {lo}" if hi is None else f"<= {hi}" if lo is None
               else f"in [{lo}, {hi}]")
        raise ParameterError("out of range", block=block, param=name,
                             expected=rng, found=v)
    return v


def count(value, block, name, *, lo=0, hi=10**8):
    """A number of agents/items: a whole number in ``[lo, hi]`` (refuses
    negative counts and sizes no machine could hold)."""
    return integer(value, block, name, lo=lo, hi=hi)
