"""What a sweep is: a scenario, a grid of overrides, seeds, metrics.

A *case* is one point of the grid and one seed. Cases are numbered in
row-major order over ``(grid dims..., seed)`` so the number is stable
across runs and resumes (``case_id = ravel_multi_index(index, shape)``).

Override names follow ``avblocks run --set``:

- ``name`` (no dot): a scenario parameter (``agents``, ``gain``, ...);
- ``simulation.<key>``: a simulation setting (``simulation.t_final``);
- ``block.param`` (any other dotted name): a numeric block parameter, handed
  to ``simulate(params={...})`` (``drive.gain``, ``lf.k_l``).

The spec is plain JSON (stored in the Zarr store's attributes). Custom
metric functions are stored *by reference* (``"package.module:function"``),
never as code: resuming imports them by name, and a store never runs what
it holds. A function that cannot be imported by name (a lambda, one defined
in a script or a notebook) serves the run that was given it; ``resume``
then needs it again (``metrics={name: fn}``), with an error saying so.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core.errors import AvError


class SweepError(AvError):
    """A sweep is ill-formed (unknown scenario, parameter or metric, a store
    that exists or is not a sweep) or could not run."""


SPEC_VERSION = 1


def _jsonable_value(v, where):
    """Grid values must survive JSON (they label the result's coordinates)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool | int | str) or v is None:
        return v
    if isinstance(v, float):
        if not math.isfinite(v):
            raise SweepError(f"grid value {v!r} of '{where}' is not finite",
                             hint="grid values must be finite numbers or strings")
        return v
    if isinstance(v, list | tuple):
        return [_jsonable_value(x, where) for x in v]
    raise SweepError(f"grid value {v!r} of '{where}' is a {type(v).__name__}",
                     hint="grid values are numbers, strings or lists of them")


def normalise_grid(grid) -> dict:
    if grid is None:
        return {}
    if not isinstance(grid, dict):
        raise SweepError("grid must be a dict {name: [values]}",
                         found=type(grid).__name__)
    out = {}
    for k, vals in grid.items():
        if not isinstance(k, str) or not k:
            raise SweepError(f"grid names must be non-empty strings, found {k!r}")
        if k == "seed":
            raise SweepError("'seed' is not a grid name", hint="use seeds=20 or "
                             "seeds=[1, 2, 3]")
        if isinstance(vals, str | bytes) or np.ndim(vals) == 0:
            vals = [vals]
        vals = [_jsonable_value(v, k) for v in list(vals)]
        if not vals:
            raise SweepError(f"grid '{k}' has no values")
        if len({repr(v) for v in vals}) != len(vals):
            raise SweepError(f"grid '{k}' repeats a value: {vals}")
        out[k] = vals
    return out


def normalise_seeds(seeds) -> list:
    if isinstance(seeds, bool):
        raise SweepError("seeds must be a count or a list of integers", found=seeds)
    if isinstance(seeds, int | np.integer):
        if not 1 <= seeds <= 10**7:
            raise SweepError("seeds must be a count from 1 to 10^7", found=seeds)
        return list(range(int(seeds)))
    try:
        out = [int(s) for s in seeds]
    except (TypeError, ValueError):
        raise SweepError("seeds must be a count or a list of integers",
                         found=repr(seeds)) from None
    if not out or len(set(out)) != len(out):
        raise SweepError("seeds must be a non-empty list of distinct integers",
                         found=out)
    return out


def scenario_source(scenario) -> dict:
    """How workers get the scenario: a built-in by name, or the file's text
    (so a remote worker and a later resume need no copy of the file)."""
    from ..scenarios import builtin_scenarios
    p = Path(str(scenario))
    builtin = builtin_scenarios()
    if not p.is_file() and str(scenario) in builtin:
        return {"name": str(scenario), "kind": "builtin"}
    if not p.is_file():
        raise SweepError(f"no built-in scenario or file named '{scenario}'",
                         hint=f"built-in scenarios: {sorted(builtin)}")
    kind = {".py": "py", ".yaml": "yaml", ".yml": "yaml", ".toml": "toml"}.get(p.suffix)
    if kind is None:
        raise SweepError(f"unknown scenario file type '{p.suffix}'",
                         hint="use a .yaml, .yml, .toml or .py scenario")
    return {"name": p.stem, "kind": kind, "path": str(p), "text": p.read_text()}


def scenario_of(src):
    """The scenario (not yet overridden) a :func:`scenario_source` names:
    the one path of :mod:`avblocks.scenarios.targets`."""
    from ..scenarios.targets import open_scenario, run_python_file
    if src["kind"] == "builtin":
        return open_scenario(src["name"])
    if src["kind"] == "py":
        return run_python_file(src["path"], src["text"])
    from ..scenarios import Scenario
    sc = Scenario(_data_of(src), src["path"])
    sc.validate()
    return sc


def _data_of(src):
    if src["kind"] == "toml":
        import tomllib
        return tomllib.loads(src["text"])
    import yaml
    return yaml.safe_load(src["text"]) or {}


def split_overrides(values: dict):
    """``(scenario overrides, block parameters)`` from override names
    (:func:`avblocks.scenarios._numeric.split_overrides`)."""
    from ..scenarios.targets import split_overrides as split
    return split(values)


def build_case(src, values: dict, seed: int):
    """``(diagram, simulate kwargs)`` of one case: the scenario with its
    overrides; the seed goes to the scenario's ``seed`` parameter when it
    has one and to ``simulate(seed=)`` always; block parameters go to
    ``simulate(params=)`` (checked against the built diagram)."""
    sc = scenario_of(src)
    if sc.accepts("seed"):
        values = {**values, "seed": int(seed)}
    d, sim = sc.with_overrides(values).build()
    sim = dict(sim)
    sim["seed"] = int(seed)
    return d, sim


def metric_reference(fn) -> str | None:
    """``"module:qualname"`` when importing that name gives ``fn`` back
    (then a resumed sweep finds it again), else None."""
    mod, qual = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if not mod or not qual or mod == "__main__" or "<" in qual:
        return None
    try:
        return f"{mod}:{qual}" if resolve_metric(f"{mod}:{qual}", "?") is fn else None
    except SweepError:
        return None


def resolve_metric(ref: str, name: str):
    """The function named by ``ref`` (``"package.module:function"``),
    imported by name; a :class:`SweepError` naming the metric otherwise."""
    import importlib
    mod, _, qual = str(ref).partition(":")
    try:
        obj = importlib.import_module(mod)
        for part in qual.split("."):
            obj = getattr(obj, part)
    except Exception as e:  # noqa: BLE001 - any import failure is the same answer
        raise SweepError(f"metric '{name}' refers to {ref!r}, which cannot be imported "
                         f"({type(e).__name__}: {e})",
                         hint="install or put on sys.path the package that defines it, or "
                              "resume with metrics={name: fn}") from None
    if not callable(obj):
        raise SweepError(f"metric '{name}' refers to {ref!r}, which is not callable")
    return obj


class Spec:
    """A sweep's definition; cheap to ship to workers."""

    def __init__(self, data: dict):
        self.data = data
        self.grid = data["grid"]
        self.seeds = data["seeds"]
        self.dims = list(self.grid) + ["seed"]
        self.shape = tuple(len(v) for v in self.grid.values()) + (len(self.seeds),)
        self.n_cases = int(np.prod(self.shape))
        self._metric_fns = None

    def case(self, case_id: int):
        """``(values {grid name: value}, seed)`` of case ``case_id``."""
        idx = np.unravel_index(int(case_id), self.shape)
        values = {k: v[i] for (k, v), i in zip(self.grid.items(), idx[:-1])}
        return {**self.data["fixed"], **values}, self.seeds[idx[-1]]

    def label(self, case_id: int) -> str:
        values, seed = self.case(case_id)
        grid = {k: values[k] for k in self.grid}
        return ", ".join(f"{k}={v}" for k, v in {**grid, "seed": seed}.items())

    def metric_fns(self) -> dict:
        """``{name: fn}``: functions handed to this process (``_callables``,
        never stored), else imported by their stored reference, else the
        built-in metric of that name."""
        if self._metric_fns is None:
            from .metrics import METRICS
            given = self.data.get("_callables") or {}
            refs = self.data.get("metric_refs") or {}
            fns = {}
            for n in self.data["metrics"]:
                if n in given:
                    fns[n] = given[n]
                elif refs.get(n):
                    fns[n] = resolve_metric(refs[n], n)
                elif n in refs or n not in METRICS:
                    raise SweepError(
                        f"metric '{n}' was a function that cannot be imported by name "
                        "(a lambda, or defined in a script); a sweep store keeps no code",
                        hint=f"resume with metrics={{'{n}': fn}}, or define the function "
                             "in an importable module")
                else:
                    fns[n] = METRICS[n]
            self._metric_fns = fns
        return self._metric_fns

    def build(self, case_id: int):
        values, seed = self.case(case_id)
        return build_case(self.data["scenario"], values, seed)


_SPEC_CACHE: dict = {}


def cached_spec(spec_data) -> Spec:
    """The :class:`Spec` of ``spec_data``, built once per worker process (the
    last one is kept: a worker runs the cases of one sweep at a time)."""
    key = spec_data["token"]
    sp = _SPEC_CACHE.get(key)
    if sp is None:
        _SPEC_CACHE.clear()
        sp = _SPEC_CACHE[key] = Spec(spec_data)
    return sp
