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
    movie: {trail: 5.0}    # optional: options for `avblocks run ... --movie`
    outcome: [{metric: all_true, signal: drive.done, what: done}]   # optional
    figures: [{plot: trajectories, file: paths.png, waypoints: drive}]  # optional

(``outcome`` and ``figures`` name built-in metrics and plots, see
:mod:`avblocks.scenarios.report`.)

Values may be plain numbers, lists, strings, ``$parameter`` references
(also inside strings: ``"${agents}"``), or a one-key mapping naming one of
the generators in :data:`GENERATORS`. Nothing in the file is executed.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.diagram import Diagram
from ..core.errors import AvError, ScenarioError, did_you_mean

_REF = re.compile(r"^\$\{?([A-Za-z_][A-Za-z0-9_]*)\}?$")
_SECTIONS = {"name", "description", "parameters", "blocks", "wires", "simulation",
             "movie", "outcome", "figures", "report"}
#: Case studies whose outcome and figures a scenario file can ask for by name
#: (``report: nest``): the ``outcome``/``figures`` of that built-in module.
REPORTS = ("nest", "formation", "flocking", "swap", "honeybee")
_SIM_KEYS = {"t_final", "dt", "solver", "log", "log_every", "seed", "realtime"}
#: ``--set`` names that go to the simulation settings when the scenario has
#: no parameter of that name (the same names as the Python scenarios').
_SIM_SHORTCUTS = {"t_final", "dt", "log_every", "solver"}


# ----------------------------------------------------------------- generators
def _random_poses(n, area, seed=0, min_separation=0.0):
    from ..utility import random_poses
    return random_poses(int(n), area=area, min_separation=min_separation, seed=seed)


def _random_positions(n, area, seed=0, min_separation=0.0, dim=2):
    from ..utility import random_positions
    p = random_positions(int(n), area=area, min_separation=min_separation, seed=seed)
    if int(dim) == 3:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


def _random_waypoints(n, count, area, seed=0):
    rng = np.random.default_rng([int(seed), 7])
    lo, hi = _area_bounds(area)
    return rng.uniform(lo, hi, (int(n), int(count), 2))


def _area_bounds(area):
    a = np.asarray(area, dtype=float)
    if a.shape == (2,):
        return np.zeros(2), a
    if a.shape == (4,):
        return a[[0, 2]], a[[1, 3]]
    raise ValueError(f"area must be [width, height] or [xmin, xmax, ymin, ymax], got {area}")


def _line(n, spacing=1.0, heading=0.0, start=(0.0, 0.0)):
    n = int(n)
    x = start[0] - spacing * np.arange(n) * np.cos(heading)
    y = start[1] - spacing * np.arange(n) * np.sin(heading)
    return np.column_stack([x, y, np.full(n, float(heading))])


def _tile(value, n):
    return np.tile(np.asarray(value, dtype=float), (int(n), 1))


def _full(shape, value):
    return np.full(tuple(int(s) for s in shape), value, dtype=float)


def _zeros(shape):
    return np.zeros(tuple(int(s) for s in shape))


def _arange(n, dtype="int64"):
    return np.arange(int(n)).astype(dtype)


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


GENERATORS = {
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


def _parse_world(spec, where):
    try:
        from ..environment import World
    except ImportError as e:
        raise ScenarioError("a 'world' needs avblocks.environment.World",
                            entry=where) from e
    if not isinstance(spec, dict):
        raise ScenarioError("a world is a mapping like {obstacles: [...], bounds: [...]}",
                            entry=where)
    try:
        return World.from_dict(spec)
    except AvError as e:
        raise ScenarioError(str(e), entry=where) from e
    except (TypeError, ValueError, KeyError) as e:
        raise ScenarioError(f"bad world: {e}", entry=where) from e


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
                    try:
                        return GENERATORS[k](**args)
                    except TypeError as e:
                        sig = inspect.signature(GENERATORS[k])
                        raise ScenarioError(f"bad arguments for '{k}': {e}",
                                            file=self.source, entry=where,
                                            hint=f"'{k}' takes {sig}") from None
                    except (ValueError, AvError) as e:
                        raise ScenarioError(f"'{k}' failed: {e}", file=self.source,
                                            entry=where) from None
                if k == "world":
                    return _parse_world(self._value(args, f"{where}.world"),
                                        f"{self.source}: {where}")
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
            elif key in params:
                params[key] = val
            elif key in _SIM_SHORTCUTS:     # --set t_final=30 as in Python scenarios
                data.setdefault("simulation", {})[key] = val
            else:
                raise ScenarioError(f"unknown parameter '{key}'", file=self.source,
                                    entry=f"--set {key}",
                                    hint=did_you_mean(key, params)
                                    + f"this scenario's parameters: {sorted(params)} "
                                         "(or t_final, dt, log_every, simulation.<setting>)")
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
        bad = set(sim) - _SIM_KEYS
        if bad:
            raise ScenarioError(f"unknown simulation setting(s) {sorted(bad)}",
                                file=self.source, entry="simulation",
                                hint=f"known: {sorted(_SIM_KEYS)}")

    def build(self):
        """The :class:`Diagram` and the keyword arguments for ``simulate``."""
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
            try:
                block = cls(**kwargs)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
            except (TypeError, ValueError) as e:
                raise ScenarioError(f"{typ}: {e}", file=self.source, entry=where,
                                    hint=f"{typ} takes {accepted}") from None
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
        sim = {k: self._value(v, f"simulation.{k}")
               for k, v in (self.data.get("simulation") or {}).items()}
        return d, sim


def _read(path: Path):
    text = path.read_text()
    try:
        if path.suffix in (".yaml", ".yml"):
            import yaml
            return yaml.safe_load(text)
        if path.suffix == ".toml":
            import tomllib
            return tomllib.loads(text)
    except Exception as e:  # noqa: BLE001 - parser errors of both formats
        raise ScenarioError(f"cannot parse: {e}", file=str(path)) from None
    raise ScenarioError("unknown scenario file type", file=str(path),
                        hint="use .yaml, .yml or .toml (or a .py file)")


def builtin_dir() -> Path:
    return Path(__file__).parent


def builtin_scenarios() -> dict:
    """``{name: path}`` of the scenarios shipped with avblocks: YAML files,
    and Python modules (``make_diagram(**params)``) for those with no YAML
    form. Where both exist the YAML file is the scenario (the module is its
    Python-API twin)."""
    py = [p for p in builtin_dir().glob("*.py") if not p.stem.startswith("_")
          and p.stem not in ("loader", "report")]
    out = {p.stem: p for p in sorted(py)}
    out.update({p.stem: p for p in sorted(builtin_dir().glob("*.yaml"))})
    return dict(sorted(out.items()))


def load_scenario(name_or_path) -> Scenario:
    """A built-in scenario by name, or a YAML/TOML file by path."""
    p = Path(str(name_or_path))
    if not p.is_file():
        b = builtin_scenarios()
        if str(name_or_path) in b and b[str(name_or_path)].suffix != ".py":
            p = b[str(name_or_path)]
        else:
            raise ScenarioError("no such scenario file or built-in scenario",
                                file=str(name_or_path),
                                hint=did_you_mean(name_or_path, b)
                                + f"built-in scenarios: {sorted(b)}")
    data = _read(p)
    sc = Scenario(data if data is not None else {}, str(p))
    sc.validate()
    return sc
