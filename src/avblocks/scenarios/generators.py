"""Generators: the one-key mappings a scenario file may use for a value.

``pose0: {random_poses: {n: $agents, area: [50, 50], seed: $seed}}`` calls
``GENERATORS["random_poses"](n=..., area=..., seed=...)``. The generic ones
(random poses and positions, lines, tiles, guards, ...) are here; each case
study module adds the geometry it owns (its own ``GENERATORS`` mapping: the
nest's hexagon, the swap's circle, the formation's references and corridor,
the learning tasks' seeded starts).
Every generator refuses an array past the scenario memory limit before
allocating it.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ParameterError
from ..core.params import count as _count
from ..core.params import integer as _integer
from . import drone_formation, formation, honeybee, navigation, nest, pursuit, scenes, spread, swap
from .limits import budget as _budget


def _n(value, name, lo=0):
    return _count(value, None, name, lo=lo, hi=10**12)


def _shape(shape, name):
    if isinstance(shape, (int, float)) and not isinstance(shape, bool):
        shape = [shape]
    if not isinstance(shape, (list, tuple)):
        raise ParameterError("a shape is a list of whole numbers", param=name,
                             found=repr(shape)[:60])
    return tuple(_n(v, f"{name}[{i}]") for i, v in enumerate(shape))


def _random_poses(n, area, seed=0, min_separation=0.0):
    from ..utility import random_poses
    n = _n(n, "n")
    _budget(3 * n, "random_poses")
    return random_poses(n, area=area, min_separation=min_separation,
                        seed=_integer(seed, None, "seed"))


def _random_positions(n, area, seed=0, min_separation=0.0, dim=2):
    from ..utility import random_positions
    n = _n(n, "n")
    dim = _integer(dim, None, "dim", lo=2, hi=3)
    _budget(dim * n, "random_positions")
    p = random_positions(n, area=area, min_separation=min_separation,
                         seed=_integer(seed, None, "seed"))
    if dim == 3:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


def _random_waypoints(n, count, area, seed=0):
    n, count = _n(n, "n"), _n(count, "count", lo=1)
    _budget(2 * n * count, "random_waypoints")
    rng = np.random.default_rng([_integer(seed, None, "seed", lo=0), 7])
    lo, hi = _area_bounds(area)
    return rng.uniform(lo, hi, (n, count, 2))


def _area_bounds(area):
    a = np.asarray(area, dtype=float)
    if a.shape == (2,):
        return np.zeros(2), a
    if a.shape == (4,):
        return a[[0, 2]], a[[1, 3]]
    raise ValueError(f"area must be [width, height] or [xmin, xmax, ymin, ymax], got {area}")


def _line(n, spacing=1.0, heading=0.0, start=(0.0, 0.0)):
    n = _n(n, "n")
    _budget(3 * n, "line_poses")
    spacing, heading = float(spacing), float(heading)
    x = start[0] - spacing * np.arange(n) * np.cos(heading)
    y = start[1] - spacing * np.arange(n) * np.sin(heading)
    return np.column_stack([x, y, np.full(n, float(heading))])


def _tile(value, n):
    v = np.asarray(value, dtype=float)
    n = _n(n, "n")
    _budget(n * max(v.size, 1), "tile")
    return np.tile(v, (n, 1))


def _full(shape, value):
    shape = _shape(shape, "shape")
    _budget(np.prod(shape, dtype=object), "full")
    return np.full(shape, value, dtype=float)


def _zeros(shape):
    shape = _shape(shape, "shape")
    _budget(np.prod(shape, dtype=object), "zeros")
    return np.zeros(shape)


def _arange(n, dtype="int64", start=0):
    """``start, start + 1, ..., start + n - 1`` (e.g. the indices of a group
    of agents for ``blocks.Select``)."""
    n = _n(n, "n")
    start = _integer(start, None, "start")
    _budget(n, "arange")
    if dtype not in ("int64", "int32", "float64", "float32"):
        raise ParameterError("dtype must be int64, int32, float64 or float32",
                             param="dtype", found=repr(dtype)[:40])
    return np.arange(start, start + n).astype(dtype)


def _item(values, index):
    """One element of a list parameter: ``{item: {values: $speed, index: 1}}``."""
    v = list(np.atleast_1d(np.asarray(values, dtype=object)))
    i = _integer(index, None, "index", lo=-len(v), hi=len(v) - 1)
    return v[i]


def _add(a, b):
    """``a + b`` (whole numbers stay whole: ``n: {add: {a: $agents, b: $scouts}}``)."""
    if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (a, b)):
        return int(a) + int(b)
    return np.asarray(a, float) + np.asarray(b, float) if np.ndim(a) or np.ndim(b) \
        else float(a) + float(b)


def _multiply(a, b):
    return np.asarray(a, float) * np.asarray(b, float) if np.ndim(a) or np.ndim(b) \
        else float(a) * float(b)


def _uniform(low, high, shape, seed=0, stream=0):
    """Uniform draws from ``numpy.random.default_rng([seed, stream])``."""
    rng = np.random.default_rng([int(seed), int(stream)])
    return rng.uniform(float(low), float(high), tuple(int(s) for s in shape))


def _first_true(n, k):
    m = np.zeros(int(n), dtype=bool)
    m[:min(int(k), int(n))] = True
    return m


def _disc(radius):
    from ..environment import Disc
    return Disc(float(radius))


_OPS = {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal,
        "==": np.equal, "!=": np.not_equal}


def _guard(input=None, index=(), op=">=", value=0.0, all=None, near=None, radius=None):
    """A transition guard from data: ``u[input][index] <op> value``; or,
    with ``near: [x, y]`` and ``radius``, whether each agent's position
    (the first two columns of ``u[input]``) lies within ``radius`` of that
    point, ``dx^2 + dy^2 <= radius^2``; or the conjunction of several
    (``all: [{input, index, op, value}, ...]``)."""
    if all is not None:
        parts = [_guard(**g) for g in all]

        def both(u, xp):
            out = parts[0](u, xp)
            for g in parts[1:]:
                out = out & g(u, xp)
            return out
        return both
    if op not in _OPS:
        raise ValueError(f"op must be one of {sorted(_OPS)}, got {op!r}")
    if input is None:
        raise ValueError("a guard names its 'input' (an input port of the block)")
    if near is not None or radius is not None:
        return _near_guard(str(input), near, radius)
    idx = tuple(int(i) for i in np.atleast_1d(index)) if np.size(index) else ()
    name, v, opname = str(input), float(value), op

    def guard(u, xp):
        x = u[name][idx] if idx else u[name]
        return {"<": x < v, "<=": x <= v, ">": x > v, ">=": x >= v, "==": x == v,
                "!=": x != v}[opname]
    return guard


def _near_guard(name, near, radius):
    c = np.asarray(near, dtype=float).ravel()
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f"'near' must be a point [x, y], got {near!r:.60}")
    r = float(radius) if radius is not None else float("nan")
    if not (np.isfinite(r) and r >= 0):
        raise ValueError(f"'radius' must be a finite number >= 0, got {radius!r:.60}")
    cx, cy, r2 = c[0], c[1], r ** 2

    def guard(u, xp):
        dx = u[name][:, 0] - cx
        dy = u[name][:, 1] - cy
        return dx * dx + dy * dy <= r2
    return guard


#: the generic generators; each case study adds its own (its ``GENERATORS``)
GENERATORS = {
    "disc": _disc,
    "guard": _guard,
    "add": _add,
    "multiply": _multiply,
    "item": _item,
    "uniform": _uniform,
    "first_true": _first_true,
    "random_poses": _random_poses,
    "random_positions": _random_positions,
    "random_waypoints": _random_waypoints,
    "line_poses": _line,
    "tile": _tile,
    "full": _full,
    "zeros": _zeros,
    "arange": _arange,
}
for _case_study in (drone_formation, formation, honeybee, nest, swap, pursuit, spread, navigation,
                    scenes):
    GENERATORS.update(_case_study.GENERATORS)
