"""What a command names, turned into a scenario and then a diagram: the one path.

Every entry point (``avblocks run``, ``avblocks diagram``, a sweep's cases,
the editor) goes the same way, each step once and in one place::

    target (built-in name | .yaml/.toml file | .py file)
      -- open_scenario ------------> Scenario        (data: loader.py)
                                     PythonScenario  (a module's names: here)
      -- .with_overrides(--set) ---> the same kind; keys split once by
                                     _numeric.split_overrides
      -- .build(output_dir) -------> (Diagram, simulate kwargs); block.param
                                     values checked once by _numeric.resolve
      -- .hooks(diagram, sim) -----> outcome / figures (report.py)
      -- .movie() -----------------> movie options

:func:`load_any` is those steps; :func:`parse_overrides` reads ``--set
key=value`` items. The other way, ``Scenario`` -> YAML, is
:func:`avblocks.scenarios.document.dump_yaml`.
"""

from __future__ import annotations

import inspect
from pathlib import Path

from ..core.errors import AvError, ScenarioError, did_you_mean
from ._numeric import resolve, split_overrides


def parse_overrides(items):
    """``{key: value}`` from ``--set key=value`` items (values read as YAML,
    so ``3`` is an int and ``[1, 2]`` a list; within the limits a scenario
    file's values have, see :mod:`avblocks.scenarios.limits`)."""
    import yaml

    from .files import yaml_value
    out = {}
    for it in items or []:
        if "=" not in it:
            raise ScenarioError(f"--set needs key=value, found '{it}'", entry="--set")
        k, v = it.split("=", 1)
        try:
            out[k.strip()] = yaml_value(v, f"--set {k.strip()}")
        except yaml.YAMLError:
            out[k.strip()] = v
    return out


class PythonScenario:
    """A scenario given as Python names: ``make_diagram(**params)``
    (returning a Diagram or ``(Diagram, simulate_kwargs)``) or ``diagram``,
    with optional ``simulation`` and ``MOVIE`` dicts and ``outcome`` /
    ``figures`` hooks (:mod:`avblocks.scenarios.report`). The Python twin of
    :class:`~avblocks.scenarios.loader.Scenario`: the same ``with_overrides``,
    ``build``, ``hooks`` and ``movie``."""

    def __init__(self, ns, source, name=None, overrides=None):
        self.ns = ns
        self.source = str(source)
        self.name = name or Path(self.source).stem
        self.overrides = dict(overrides or {})

    def accepts(self, key) -> bool:
        """Whether ``key`` is one of this scenario's parameters."""
        fn = self.ns.get("make_diagram")
        if fn is None:
            return False
        sig = inspect.signature(fn)
        return key in sig.parameters or any(p.kind == p.VAR_KEYWORD
                                            for p in sig.parameters.values())

    def with_overrides(self, overrides, *, user=False) -> PythonScenario:
        """A copy with ``--set`` values: ``make_diagram`` arguments,
        ``simulation.<key>`` settings and ``block.param`` numeric values
        (``user``: as :meth:`Scenario.with_overrides`'s; Python code
        names the files it reads itself)."""
        plain, _numeric = split_overrides(overrides)
        params = [k for k in plain if not k.startswith("simulation.")]
        fn = self.ns.get("make_diagram")
        if fn is not None:
            unknown = [k for k in params if not self.accepts(k)]
            if unknown:
                sig = inspect.signature(fn)
                raise ScenarioError(f"unknown parameter(s) {unknown}", file=self.source,
                                    entry="--set",
                                    hint=did_you_mean(unknown[0], sig.parameters)
                                    + f"this scenario's parameters: {list(sig.parameters)} "
                                      "(or simulation.t_final, simulation.dt, ...)")
        elif params and "diagram" in self.ns:
            raise ScenarioError("this file defines `diagram`, so it takes no --set; "
                                "define make_diagram(**params) instead", file=self.source)
        return PythonScenario(self.ns, self.source, self.name,
                              {**self.overrides, **dict(overrides or {})})

    def build(self, output_dir=None):
        """``(Diagram, simulate kwargs)``."""
        from ..core.diagram import Diagram
        ns, source = self.ns, self.source
        plain, numeric = split_overrides(self.overrides)
        params = {k: v for k, v in plain.items() if not k.startswith("simulation.")}
        sim = dict(ns.get("simulation") or {})
        if "make_diagram" in ns:
            try:
                out = ns["make_diagram"](**params)
            except AvError as e:
                raise ScenarioError(str(e), file=source, entry="--set") from None
            if isinstance(out, tuple):
                d, extra = out
                sim.update(extra)
            else:
                d = out
        elif "diagram" in ns:
            d = ns["diagram"]
        else:
            raise ScenarioError("a Python scenario must define make_diagram(**params) or "
                                "a variable `diagram`", file=source)
        if not isinstance(d, Diagram):
            raise ScenarioError("make_diagram()/diagram must be an avblocks.Diagram",
                                file=source, hint=f"found {type(d).__name__}")
        sim.update({k.split(".", 1)[1]: v for k, v in plain.items()
                    if k.startswith("simulation.")})
        if numeric:
            sim["params"] = {**(sim.get("params") or {}), **resolve(d, numeric, source)}
        return d, sim

    def hooks(self, diagram=None, sim=None):
        """The module's ``outcome`` and ``figures`` (a :class:`report.Hooks`)."""
        from .report import hooks_from_namespace
        return hooks_from_namespace(self.ns, self.overrides)

    def movie(self) -> dict:
        return dict(self.ns.get("MOVIE") or {})


def from_namespace(ns, overrides, source):
    """(diagram, simulate kwargs, movie options) from a scenario module's
    names (see :class:`PythonScenario`)."""
    sc = PythonScenario(ns, source).with_overrides(overrides)
    d, sim = sc.build()
    return d, sim, sc.movie()


def run_python_file(path, text=None) -> PythonScenario:
    """Run a user's Python scenario file (it may import anything it likes;
    ``text``: its source, when it is not read from ``path``)."""
    import runpy
    path = Path(path)
    try:
        if text is None:
            ns = runpy.run_path(str(path), run_name="avblocks_scenario")
        else:
            ns = {"__name__": "avblocks_scenario", "__file__": str(path)}
            exec(compile(text, str(path), "exec"), ns)  # noqa: S102 - the user's own file
    except AvError:
        raise
    except Exception as e:  # noqa: BLE001 - the user's file failed
        raise ScenarioError(f"running the file failed: {type(e).__name__}: {e}",
                            file=str(path)) from e
    return PythonScenario(ns, str(path), path.stem)


def open_scenario(target):
    """The scenario a command names, not yet overridden or built: a
    built-in name (its YAML file, or its Python module where it has no
    file), a ``.py`` file (run), or a YAML/TOML file."""
    import importlib

    from .loader import builtin_scenarios, load_scenario
    p = Path(str(target))
    builtin = builtin_scenarios()
    if not p.is_file() and str(target) in builtin and builtin[str(target)].suffix == ".py":
        mod = importlib.import_module(f"avblocks.scenarios.{target}")
        return PythonScenario(vars(mod), str(target), str(target))
    if p.suffix == ".py":
        if not p.is_file():
            raise ScenarioError("no such file", file=str(target))
        return run_python_file(p)
    return load_scenario(target)


class Loaded(tuple):
    """``(diagram, simulate kwargs, name, movie options)``, what
    :func:`load_any` returns, with the scenario's ``hooks`` (its
    ``outcome`` and ``figures``) as an attribute."""

    def __new__(cls, d, sim, name, movie, hooks=None):
        self = super().__new__(cls, (d, sim, name, movie))
        self.hooks = hooks
        return self


def load_python(path: Path, overrides):
    """A user's Python scenario file, overridden and built (a :class:`Loaded`)."""
    return _loaded(run_python_file(path).with_overrides(overrides), None)


def _loaded(sc, out):
    d, sim = sc.build(output_dir=out)
    return Loaded(d, sim, sc.name, sc.movie(), sc.hooks(d, sim))


def load_any(target, overrides, out=None):
    """(diagram, simulate kwargs, name, movie options) from a built-in
    name, a YAML/TOML file or a .py file (``out``: the output folder a
    scenario file's blocks may write to), as a :class:`Loaded` whose
    ``.hooks`` holds the scenario's ``outcome`` and ``figures`` (see
    :mod:`avblocks.scenarios.report`)."""
    return _loaded(open_scenario(target).with_overrides(overrides, user=True), out)
