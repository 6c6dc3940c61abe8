"""Scenario files: a diagram declared as data (YAML or TOML), never code.

A scenario file has five sections::

    name: waypoints
    description: N unicycles drive through random waypoints.
    parameters:            # the knobs; change with `--set agents=300`
      agents: 15
      seed: 1
    blocks:                # name -> {type: <family.Class>, <param>: <value>}
      fleet:
        type: vehicles.Unicycle
        pose0: {random_poses: {n: $agents, area: [50, 50], seed: $seed}}
      drive:
        type: controllers.PointToPoint
        waypoints: {random_waypoints: {n: $agents, count: 3, area: [50, 50], seed: $seed}}
    wires:                 # [source output, destination input]
      - [fleet.pose, drive.pose]
      - [drive.cmd, fleet.cmd]
    simulation: {t_final: 60, dt: 0.01, solver: rk4, log: [fleet.pose], seed: $seed}
    params: {drive.gain: 2.0}   # optional: numeric block parameters (block.param)
    movie: {trail: 5.0}    # optional: options for `avblocks run ... --movie`
    outcome: [{metric: all_true, signal: drive.done, what: done}]   # optional
    figures: [{plot: trajectories, file: paths.png, waypoints: drive}]  # optional

(``outcome`` and ``figures`` name built-in metrics and plots, see
:mod:`avblocks.scenarios.report`.)

Values may be plain numbers, lists, strings, ``$parameter`` references
(also inside strings: ``"${agents}"``), or a one-key mapping naming one of
the generators in :data:`GENERATORS`. Nothing in the file is executed.

``params`` sets numeric parameters of the built blocks by dotted path (see
:mod:`avblocks.scenarios._numeric`); ``--set drive.gain=3`` overrides them.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.diagram import Diagram
from ..core.errors import AvError, ParameterError, ScenarioError, did_you_mean
from ..core.params import count as _count
from ..core.params import integer as _integer
from ._numeric import is_numeric_key, resolve

_REF = re.compile(r"^\$\{?([A-Za-z_][A-Za-z0-9_]*)\}?$")
_SECTIONS = {"name", "description", "parameters", "blocks", "wires", "simulation",
             "movie", "params", "outcome", "figures", "report"}
#: Case studies whose outcome and figures a scenario file can ask for by name
#: (``report: nest``): the ``outcome``/``figures`` of that built-in module.
REPORTS = ("nest", "formation", "flocking", "swap", "honeybee")
_SIM_KEYS = {"t_final", "dt", "solver", "log", "log_every", "seed", "realtime"}
#: ``--set`` names that go to the simulation settings when the scenario has
#: no parameter of that name (the same names as the Python scenarios').
_SIM_SHORTCUTS = {"t_final", "dt", "log_every", "solver"}
#: Block arguments (and movie options) naming files a scenario writes: they
#: must stay inside the output folder.
WRITE_KEYS = {"path", "movie", "file", "filename", "output", "save", "save_path"}
#: ... and files it reads: they must lie under the scenario file's folder.
READ_KEYS = {"background", "image", "map", "geojson"}


# ------------------------------------------------------------------ limits
#: Largest scenario file read (bytes).
MAX_FILE_BYTES = 10 * 1024**2
#: Largest number of values a YAML document may expand to through
#: anchors and aliases (a "billion laughs" file is refused, not expanded).
MAX_YAML_VALUES = 1_000_000


def memory_limit() -> int:
    """Bytes a scenario may ask for (generated arrays; the log is checked by
    ``simulate``): ``AVBLOCKS_MAX_MEMORY`` (e.g. ``8e9``) or half the
    physical memory, at most 8 GB."""
    import os
    env = os.environ.get("AVBLOCKS_MAX_MEMORY")
    if env:
        try:
            return int(float(env))
        except (ValueError, OverflowError):
            raise ScenarioError(f"AVBLOCKS_MAX_MEMORY must be a number of bytes, "
                                f"found {env!r}") from None
    try:
        phys = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        phys = 16 * 1024**3
    return int(min(8e9, phys / 2))


def _budget(elements, what):
    """Refuse an array of ``elements`` float64 values past the memory limit,
    before allocating it."""
    need = 8 * int(elements)
    lim = memory_limit()
    if need > lim:
        raise ParameterError(f"{what} would take {need / 1e9:.3g} GB", param=what,
                             expected=f"<= {lim / 1e9:.3g} GB (AVBLOCKS_MAX_MEMORY)",
                             hint="use fewer agents/points")


def _n(value, name, lo=0):
    return _count(value, None, name, lo=lo, hi=10**12)


def _shape(shape, name):
    if isinstance(shape, (int, float)) and not isinstance(shape, bool):
        shape = [shape]
    if not isinstance(shape, (list, tuple)):
        raise ParameterError("a shape is a list of whole numbers", param=name,
                             found=repr(shape)[:60])
    return tuple(_n(v, f"{name}[{i}]") for i, v in enumerate(shape))


# ----------------------------------------------------------------- generators
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


def _arange(n, dtype="int64"):
    n = _n(n, "n")
    _budget(n, "arange")
    if dtype not in ("int64", "int32", "float64", "float32"):
        raise ParameterError("dtype must be int64, int32, float64 or float32",
                             param="dtype", found=repr(dtype)[:40])
    return np.arange(n).astype(dtype)


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


def _nest_hexagon(agents, density):
    from .nest import hexagon, hexagon_radius
    return hexagon(hexagon_radius(int(agents), float(density)))


def _nest_poses(agents, density, scouts, seed):
    from .nest import hexagon_radius, nest_poses
    return nest_poses(int(agents), hexagon_radius(int(agents), float(density)), scouts, seed)


def _circle_swap(n, radius, jitter=0.0, seed=1, which="start"):
    from .swap import circle_swap
    start, goal = circle_swap(int(n), float(radius), float(jitter), seed)
    if which == "start":
        return start
    if which == "goal":
        return goal[:, None, :]
    raise ValueError(f"which must be 'start' or 'goal', got {which!r}")


def _speed_caps(n, v_max, spread, seed=1, stream=10):
    rng = np.random.default_rng([int(seed), int(stream)])
    return float(v_max) * (1.0 - float(spread) * rng.uniform(0.0, 1.0, int(n)))


def _formation_start(n, spacing, offset, seed):
    from .formation import start_poses
    return start_poses(int(n), float(spacing), float(offset), seed)


def _formation_refs(n, spacing, d, tree="star", state="wedge"):
    from .formation import formation_references
    leader, refs = formation_references(int(n), float(spacing), float(d), tree)
    if state == "leader":
        return leader
    if state not in refs:
        raise ValueError(f"state must be one of {sorted(refs)} or 'leader', got {state!r}")
    return refs[state]


def _formation_switch(n, spacing, which="in"):
    from .formation import switch_points
    x_in, x_out = switch_points(int(n), float(spacing))
    return {"in": x_in, "out": x_out}[which]


def _corridor(x0, x1, width, wall=4.0):
    from .formation import corridor_world
    return corridor_world(float(x0), float(x1), float(width), float(wall))


def _disc(radius):
    from ..environment import Disc
    return Disc(float(radius))


_OPS = {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal,
        "==": np.equal, "!=": np.not_equal}


def _guard(input=None, index=(), op=">=", value=0.0, all=None):
    """A transition guard from data: ``u[input][index] <op> value``, or the
    conjunction of several (``all: [{input, index, op, value}, ...]``)."""
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
    idx = tuple(int(i) for i in np.atleast_1d(index)) if np.size(index) else ()
    name, v, opname = str(input), float(value), op

    def guard(u, xp):
        x = u[name][idx] if idx else u[name]
        return {"<": x < v, "<=": x <= v, ">": x > v, ">=": x >= v, "==": x == v,
                "!=": x != v}[opname]
    return guard


def _team_size(agents=None, followers=None):
    """``agents`` when given, else ``followers + 1`` (a leader and its
    followers)."""
    if agents is not None:
        return int(agents)
    if followers is None:
        raise ValueError("give agents or followers")
    return int(followers) + 1


GENERATORS = {
    "team_size": _team_size,
    "formation_start": _formation_start,
    "formation_references": _formation_refs,
    "formation_switch": _formation_switch,
    "corridor": _corridor,
    "disc": _disc,
    "guard": _guard,
    "multiply": _multiply,
    "uniform": _uniform,
    "first_true": _first_true,
    "nest_hexagon": _nest_hexagon,
    "nest_poses": _nest_poses,
    "circle_swap": _circle_swap,
    "speed_caps": _speed_caps,
    "random_poses": _random_poses,
    "random_positions": _random_positions,
    "random_waypoints": _random_waypoints,
    "line_poses": _line,
    "tile": _tile,
    "full": _full,
    "zeros": _zeros,
    "arange": _arange,
}


# ------------------------------------------------------------------ registry
def block_registry(code_blocks=False) -> dict:
    """``{"vehicles.Unicycle": class, ...}`` for every public block class
    that a scenario file can name (``code_blocks=True``: also those that
    take Python code, such as ``blocks.Function``)."""
    import importlib

    from ..core.block import Block

    reg = {}
    for fam in ("blocks", "vehicles", "controllers", "environment", "viz"):
        try:
            mod = importlib.import_module(f"avblocks.{fam}")
        except ImportError:  # optional family whose extra is missing
            continue
        for name in getattr(mod, "__all__", dir(mod)):
            obj = getattr(mod, name, None)
            if inspect.isclass(obj) and issubclass(obj, Block) and obj is not Block:
                if name == "Function" and not code_blocks:   # takes Python code
                    continue
                reg[f"{fam}.{name}"] = obj
    return reg


_WORLD_KEYS = {"obstacles", "bounds", "walls", "image", "geojson", "wkt"}


def _obstacle(ob, where, source=None):
    from ..environment.world import Circle
    if isinstance(ob, dict):
        if set(ob) == {"circle"} and isinstance(ob["circle"], dict):
            ob = ob["circle"]
        if set(ob) == {"center", "radius"}:
            c = np.asarray(ob["center"], dtype=float)
            return Circle(tuple(c.tolist()) if c.ndim == 1 else c, float(ob["radius"]))
        if set(ob) == {"polygon"}:
            return ob["polygon"]
        raise ScenarioError("an obstacle is a list of [x, y] vertices, {polygon: "
                            "[[x, y], ...]} or {circle: {center: [x, y], radius: r}}",
                            file=source, entry=where,
                            hint=f"found keys {sorted(map(str, ob))}")
    return ob


def _parse_world(spec, where, folder, source=None):
    """A :class:`~avblocks.environment.World` from a scenario mapping::

        world:
          bounds: [0, 0, 50, 50]          # xmin, ymin, xmax, ymax
          walls: true
          obstacles: [[[10, 10], [20, 10], [15, 20]], {circle: {center: [30, 30], radius: 4}}]
        # or instead of obstacles: image: {path: map.png, resolution: 0.05},
        #   geojson: obstacles.geojson (files under the scenario's folder), wkt: "POLYGON(...)"
    """
    import json

    from .paths import inside
    try:
        from ..environment import World
    except ImportError as e:
        raise ScenarioError("a 'world' needs avblocks.environment.World",
                            file=source, entry=where) from e
    if not isinstance(spec, dict):
        raise ScenarioError("a world is a mapping like {obstacles: [...], bounds: [...]}",
                            file=source, entry=where)
    unknown = set(map(str, spec)) - _WORLD_KEYS
    if unknown:
        raise ScenarioError(f"unknown world key(s) {sorted(unknown)}", file=source,
                            entry=where, hint=f"known: {sorted(_WORLD_KEYS)}")
    sources = [k for k in ("obstacles", "image", "geojson", "wkt") if k in spec]
    if len(sources) > 1:
        raise ScenarioError(f"give the obstacles one way, not {sources}", file=source,
                            entry=where)
    kw = {}
    if spec.get("bounds") is not None:
        kw["bounds"] = spec["bounds"]
    if "walls" in spec:
        if not isinstance(spec["walls"], bool):
            raise ScenarioError("walls must be true or false", file=source,
                                entry=f"{where}.walls")
        kw["walls"] = spec["walls"]
    try:
        if "image" in spec:
            im = spec["image"]
            if not isinstance(im, dict) or "path" not in im:
                raise ScenarioError("image is {path: file, resolution: metres per pixel,"
                                    " origin: [x, y]}", file=source, entry=f"{where}.image")
            opts = {k: v for k, v in im.items() if k != "path"}
            bad = set(opts) - {"resolution", "origin", "occupied_thresh", "negate"}
            if bad:
                raise ScenarioError(f"unknown image option(s) {sorted(map(str, bad))}",
                                    file=source, entry=f"{where}.image")
            path = inside(im["path"], folder, what=f"{where}.image.path", source=source,
                          must_exist=True)
            return World.from_image(str(path), **opts, **kw)
        if "geojson" in spec:
            g = spec["geojson"]
            if isinstance(g, str):
                path = inside(g, folder, what=f"{where}.geojson", source=source,
                              must_exist=True)
                g = json.loads(path.read_text(encoding="utf-8"))
            return World.from_geojson(g, **kw)
        if "wkt" in spec:
            return World.from_wkt(spec["wkt"], **kw)
        obs = spec.get("obstacles") or []
        if not isinstance(obs, list):
            raise ScenarioError("obstacles must be a list", file=source,
                                entry=f"{where}.obstacles")
        return World([_obstacle(o, f"{where}.obstacles[{j}]", source) for j, o in enumerate(obs)],
                     **kw)
    except ScenarioError:
        raise
    except AvError as e:
        raise ScenarioError(str(e), file=source, entry=where) from None
    except (TypeError, ValueError, KeyError, OverflowError, MemoryError, OSError,
            RecursionError) as e:
        raise ScenarioError(f"bad world: {type(e).__name__}: {e}", file=source,
                            entry=where) from None


@dataclass
class Scenario:
    """A parsed scenario: its data, with parameters substituted on build."""

    data: dict
    source: str = "<dict>"
    params: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        return str(self.data.get("name", Path(self.source).stem))

    @property
    def folder(self) -> Path:
        """The folder a scenario file may read from (its own)."""
        if self.source.startswith("<"):
            return Path.cwd()
        return Path(self.source).resolve().parent

    @property
    def description(self) -> str:
        return str(self.data.get("description", ""))

    # ----------------------------------------------------------- values
    def _value(self, v, where):
        if isinstance(v, str):
            m = _REF.match(v.strip())
            if m:
                key = m.group(1)
                if key not in self.params:
                    raise ScenarioError(f"unknown parameter reference '${key}'",
                                        file=self.source, entry=where,
                                        hint=did_you_mean(key, self.params)
                                        + f"known parameters: {sorted(self.params)}")
                return self.params[key]
            return v
        if isinstance(v, list):
            return [self._value(x, f"{where}[{i}]") for i, x in enumerate(v)]
        if isinstance(v, dict):
            if len(v) == 1:
                (k, args), = v.items()
                if k in GENERATORS:
                    args = self._value(args, f"{where}.{k}")
                    if not isinstance(args, dict):
                        raise ScenarioError(f"generator '{k}' takes a mapping of "
                                            "arguments", file=self.source, entry=where)
                    sig = inspect.signature(GENERATORS[k])
                    try:
                        sig.bind(**args)
                    except TypeError as e:
                        raise ScenarioError(f"bad arguments for '{k}': {e}",
                                            file=self.source, entry=where,
                                            hint=f"'{k}' takes {sig}") from None
                    try:
                        return GENERATORS[k](**args)
                    except MemoryError:
                        raise ScenarioError(f"'{k}' ran out of memory", file=self.source,
                                            entry=where, hint="use fewer agents/points"
                                            ) from None
                    except (TypeError, ValueError, AvError, OverflowError,
                            IndexError, RecursionError) as e:
                        raise ScenarioError(f"'{k}' failed: {e}", file=self.source,
                                            entry=where, hint=f"'{k}' takes {sig}"
                                            ) from None
                if k == "world":
                    return _parse_world(self._value(args, f"{where}.world"),
                                        where, self.folder, self.source)
            return {k: self._value(x, f"{where}.{k}") for k, x in v.items()}
        return v

    def with_overrides(self, overrides: dict) -> Scenario:
        """A copy with ``--set`` values applied: parameter names, or
        ``simulation.<key>``."""
        import copy
        data = copy.deepcopy(self.data)
        params = dict(data.get("parameters") or {})
        for key, val in overrides.items():
            if key.startswith("simulation."):
                sub = key.split(".", 1)[1]
                if sub not in _SIM_KEYS:
                    raise ScenarioError(f"unknown simulation setting '{sub}'",
                                        file=self.source, entry=f"--set {key}",
                                        hint=did_you_mean(sub, _SIM_KEYS)
                                        + f"known: {sorted(_SIM_KEYS)}")
                data.setdefault("simulation", {})[sub] = val
            elif is_numeric_key(key):          # block.param: checked on build
                data["params"] = {**(data.get("params") or {}), key: val}
            elif key in params:
                params[key] = val
            elif key in _SIM_SHORTCUTS:     # --set t_final=30 as in Python scenarios
                data.setdefault("simulation", {})[key] = val
            else:
                raise ScenarioError(f"unknown parameter '{key}'", file=self.source,
                                    entry=f"--set {key}",
                                    hint=did_you_mean(key, params)
                                    + f"this scenario's parameters: {sorted(params)} "
                                      "(or t_final, dt, log_every, simulation.<setting>, "
                                      "block.param)")
        data["parameters"] = params
        return Scenario(data, self.source)

    # ------------------------------------------------------------- build
    def validate(self):
        d = self.data
        if not isinstance(d, dict):
            raise ScenarioError("a scenario must be a mapping with sections "
                                f"{sorted(_SECTIONS)}", file=self.source)
        unknown = set(d) - _SECTIONS
        if unknown:
            raise ScenarioError(f"unknown section(s) {sorted(unknown)}", file=self.source,
                                hint=f"sections are {sorted(_SECTIONS)}")
        if not isinstance(d.get("movie") or {}, dict):
            raise ScenarioError("'movie' must be a mapping of movie options",
                                file=self.source, entry="movie")
        if d.get("report") is not None and d["report"] not in REPORTS:
            raise ScenarioError(f"unknown report '{d['report']}'", file=self.source,
                                entry="report",
                                hint=did_you_mean(d["report"], REPORTS)
                                + f"reports: {list(REPORTS)}")
        if not isinstance(d.get("blocks"), dict) or not d["blocks"]:
            raise ScenarioError("'blocks' must map block names to their settings",
                                file=self.source, entry="blocks")
        params = d.get("parameters") or {}
        if not isinstance(params, dict):
            raise ScenarioError("'parameters' must be a mapping", file=self.source,
                                entry="parameters")
        wires = d.get("wires") or []
        if not isinstance(wires, list):
            raise ScenarioError("'wires' must be a list of [source, destination]",
                                file=self.source, entry="wires")
        sim = d.get("simulation") or {}
        if not isinstance(sim, dict):
            raise ScenarioError("'simulation' must be a mapping", file=self.source,
                                entry="simulation")
        if not isinstance(d.get("params") or {}, dict):
            raise ScenarioError("'params' must map 'block.param' to values",
                                file=self.source, entry="params")
        bad = set(sim) - _SIM_KEYS
        if bad:
            raise ScenarioError(f"unknown simulation setting(s) {sorted(bad)}",
                                file=self.source, entry="simulation",
                                hint=f"known: {sorted(_SIM_KEYS)}")

    def output_dir(self, output_dir=None) -> Path:
        """Where this scenario's files go: ``output_dir`` or
        ``avblocks-out/<name>`` (the name made safe as one folder name)."""
        from .paths import safe_name
        if output_dir is not None:
            return Path(output_dir)
        return Path("avblocks-out") / safe_name(self.name)

    def _confine(self, kwargs, where, out):
        """Paths a file names: writes only inside ``out``, reads only under
        the scenario's own folder."""
        from .paths import inside
        for k, v in kwargs.items():
            if not isinstance(v, (str, Path)):
                continue
            if k in WRITE_KEYS:
                kwargs[k] = inside(v, out, what=f"{where}.{k}", source=self.source)
            elif k in READ_KEYS:
                kwargs[k] = inside(v, self.folder, what=f"{where}.{k}", source=self.source,
                                   must_exist=True)
        return kwargs

    def movie_options(self) -> dict:
        """The ``movie:`` section, its file names confined to the scenario's folder."""
        opts = dict(self.data.get("movie") or {})
        return self._confine(opts, "movie", self.folder)

    def build(self, output_dir=None):
        """The :class:`Diagram` and the keyword arguments for ``simulate``.

        ``output_dir`` is the only folder the scenario's blocks may write to
        (a Scope's ``path``, an animation's ``movie``: relative names land
        in it, names leaving it are refused); default ``avblocks-out/<name>``.
        Files a scenario reads (backgrounds, map images) must lie under the
        scenario file's own folder."""
        try:
            return self._build(self.output_dir(output_dir))
        except RecursionError:
            raise ScenarioError("the file nests values too deeply", file=self.source
                                ) from None

    def _build(self, out):
        self.validate()
        self.params = dict(self.data.get("parameters") or {})
        reg = block_registry()
        d = Diagram(self.name)
        for name, spec in self.data["blocks"].items():
            where = f"blocks.{name}"
            if not isinstance(spec, dict) or "type" not in spec:
                raise ScenarioError("each block needs a 'type'", file=self.source,
                                    entry=where, hint="e.g. type: vehicles.Unicycle")
            typ = spec["type"]
            if not isinstance(typ, str):
                raise ScenarioError("'type' must be a block type name",
                                    file=self.source, entry=f"{where}.type",
                                    hint=f"e.g. vehicles.Unicycle, found {typ!r:.60}")
            if typ not in reg:
                import difflib
                close = difflib.get_close_matches(str(typ), list(reg), n=1, cutoff=0.6)
                raise ScenarioError(f"unknown block type '{typ}'", file=self.source,
                                    entry=f"{where}.type",
                                    hint=(f"did you mean '{close[0]}'?" if close else
                                          "run `avblocks list --blocks` for the types"))
            cls = reg[typ]
            kwargs = {k: self._value(v, f"{where}.{k}") for k, v in spec.items()
                      if k != "type"}
            sig = inspect.signature(cls.__init__)
            accepted = [p for p in sig.parameters if p != "self"]
            has_var = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
            for k in kwargs:
                if k not in accepted and not has_var:
                    raise ScenarioError(f"unknown parameter '{k}' for {typ}",
                                        file=self.source, entry=f"{where}.{k}",
                                        hint=did_you_mean(k, accepted)
                                        + f"{typ} takes {accepted}")
            kwargs = self._confine(kwargs, where, out)
            try:
                block = cls(**kwargs)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
            except MemoryError:
                raise ScenarioError(f"{typ}: out of memory", file=self.source, entry=where,
                                    hint="use fewer agents") from None
            except Exception as e:  # noqa: BLE001 - a constructor's own failure
                raise ScenarioError(f"{typ}: {type(e).__name__}: {e}", file=self.source,
                                    entry=where, hint=f"{typ} takes {accepted}") from None
            try:
                d.add(block, name=name)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
        for j, w in enumerate(self.data.get("wires") or []):
            where = f"wires[{j}]"
            if not (isinstance(w, list) and len(w) == 2 and all(isinstance(s, str)
                                                                 for s in w)):
                raise ScenarioError(
                    f"a wire is [\"block.output\", \"block.input\"], found {w!r}",
                    file=self.source, entry=where)
            refs = []
            for s in w:
                b, _, p = s.partition(".")
                if b not in d.blocks:
                    raise ScenarioError(f"wire names unknown block '{b}'",
                                        file=self.source, entry=where,
                                        hint=did_you_mean(b, d.blocks)
                                        + f"blocks: {sorted(d.blocks)}")
                try:
                    refs.append(d[b].port(p))
                except AvError as e:
                    raise ScenarioError(str(e), file=self.source, entry=where) from None
            try:
                d.connect(*refs)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
        try:
            d.build()
        except AvError as e:
            raise ScenarioError(str(e), file=self.source, entry="wires",
                                hint="every input needs exactly one wire") from None
        except Exception as e:  # noqa: BLE001 - a block's configure() failed
            raise ScenarioError(f"building the diagram failed: {type(e).__name__}: {e}",
                                file=self.source, entry="blocks") from None
        sim = {k: self._value(v, f"simulation.{k}")
               for k, v in (self.data.get("simulation") or {}).items()}
        numeric = {k: self._value(v, f"params.{k}")
                   for k, v in (self.data.get("params") or {}).items()}
        if numeric:
            sim["params"] = resolve(d, numeric, self.source, "params")
        return d, sim


def _yaml_error(e):
    """A PyYAML error in one line with its position."""
    import yaml
    if isinstance(e, yaml.MarkedYAMLError):
        m = e.problem_mark or e.context_mark
        what = " ".join(str(e.problem or e.context or "invalid YAML").split())
        if e.context and e.problem:
            what = " ".join(f"{e.problem} ({e.context})".split())
        return what + (f" at line {m.line + 1}, column {m.column + 1}" if m else "")
    return " ".join(str(e).split())


def _expanded_size(node, limit):
    """Number of values ``node`` expands to (aliases counted every time they
    are used), computed on the graph without expanding it; ``limit + 1`` as
    soon as it passes ``limit``; -1 for a recursive structure."""
    import yaml
    size, state = {}, {}
    stack = [(node, False)]
    while stack:
        n, done = stack.pop()
        key = id(n)
        if done:
            kids = _children(n, yaml)
            size[key] = min(limit + 1, 1 + sum(size[id(c)] for c in kids))
            state[key] = 2
            continue
        if state.get(key) == 2:
            continue
        if state.get(key) == 1:
            return -1
        state[key] = 1
        stack.append((n, True))
        for c in _children(n, yaml):
            if state.get(id(c)) == 1:
                return -1
            if state.get(id(c)) != 2:
                stack.append((c, False))
    return size[id(node)]


def _children(n, yaml):
    if isinstance(n, yaml.SequenceNode):
        return list(n.value)
    if isinstance(n, yaml.MappingNode):
        return [x for kv in n.value for x in kv]
    return []


def _safe_yaml(text, source):
    """``yaml.safe_load`` that refuses duplicate keys, unhashable keys and
    alias expansions past :data:`MAX_YAML_VALUES`."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    def mapping(loader, node, deep=False):
        seen = set()
        for k_node, _v in node.value:
            if k_node.tag == "tag:yaml.org,2002:merge":
                continue
            k = loader.construct_object(k_node, deep=True)
            try:
                hash(k)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    None, None, "a mapping key must be a plain value",
                    k_node.start_mark) from None
            if k in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {k!r}", k_node.start_mark)
            seen.add(k)
        return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)

    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    loader = Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        n = _expanded_size(node, MAX_YAML_VALUES)
        if n < 0:
            raise ScenarioError("anchors/aliases make a recursive structure",
                                file=source)
        if n > MAX_YAML_VALUES:
            raise ScenarioError(f"anchors/aliases expand to more than {MAX_YAML_VALUES:,} "
                                "values", file=source,
                                hint="write the data out or use a generator")
        return loader.construct_document(node)
    finally:
        loader.dispose()


def _read(path: Path):
    source = str(path)
    if path.is_dir():
        raise ScenarioError("is a folder, not a scenario file", file=source)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ScenarioError(f"the file is {size / 1e6:.1f} MB; scenario files are "
                                f"at most {MAX_FILE_BYTES / 1e6:.0f} MB", file=source)
        raw = path.read_bytes()
    except OSError as e:
        raise ScenarioError(f"cannot read: {e.strerror or e}", file=source) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ScenarioError(f"not UTF-8 text (byte 0x{raw[e.start]:02x} at offset "
                            f"{e.start})", file=source,
                            hint="save the file as UTF-8") from None
    if path.suffix in (".yaml", ".yml"):
        import yaml
        try:
            return _safe_yaml(text, source)
        except ScenarioError:
            raise
        except yaml.YAMLError as e:
            raise ScenarioError(f"cannot parse: {_yaml_error(e)}", file=source) from None
        except RecursionError:
            raise ScenarioError("cannot parse: the file nests values too deeply",
                                file=source) from None
        except Exception as e:  # noqa: BLE001 - constructors of odd YAML scalars
            raise ScenarioError(f"cannot parse: {type(e).__name__}: {e}",
                                file=source) from None
    if path.suffix == ".toml":
        import tomllib
        try:
            return tomllib.loads(text)
        except RecursionError:
            raise ScenarioError("cannot parse: the file nests values too deeply",
                                file=source) from None
        except Exception as e:  # noqa: BLE001 - tomllib errors
            raise ScenarioError(f"cannot parse: {' '.join(str(e).split())}",
                                file=source) from None
    raise ScenarioError("unknown scenario file type", file=source,
                        hint="use .yaml, .yml or .toml (or a .py file)")


def builtin_dir() -> Path:
    return Path(__file__).parent


#: modules of this package that are machinery, not scenarios
INFRASTRUCTURE = ("loader", "report", "paths", "targets")


def builtin_scenarios() -> dict:
    """``{name: path}`` of the scenarios shipped with avblocks: YAML files,
    and Python modules (``make_diagram(**params)``) for those with no YAML
    form. Where both exist the YAML file is the scenario (the module is its
    Python-API twin)."""
    py = [p for p in builtin_dir().glob("*.py") if not p.stem.startswith("_")
          and p.stem not in INFRASTRUCTURE]
    out = {p.stem: p for p in sorted(py)}
    out.update({p.stem: p for p in sorted(builtin_dir().glob("*.yaml"))})
    return dict(sorted(out.items()))


def load_scenario(name_or_path) -> Scenario:
    """A built-in scenario by name, or a YAML/TOML file by path."""
    p = Path(str(name_or_path))
    if not p.is_file():
        # a folder in the working directory named like a built-in scenario
        # never shadows it
        b = builtin_scenarios()
        if str(name_or_path) in b and b[str(name_or_path)].suffix != ".py":
            p = b[str(name_or_path)]
        elif p.is_dir():
            raise ScenarioError("is a folder, not a scenario file", file=str(name_or_path),
                                hint=f"built-in scenarios: {sorted(b)}")
        else:
            raise ScenarioError("no such scenario file or built-in scenario",
                                file=str(name_or_path),
                                hint=did_you_mean(name_or_path, b)
                                + f"built-in scenarios: {sorted(b)}")
    data = _read(p)
    sc = Scenario(data if data is not None else {}, str(p))
    sc.validate()
    return sc
