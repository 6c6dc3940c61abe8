"""Loading what a command names: a built-in scenario, a YAML/TOML file or a Python file.

One place for what ``avblocks run``, ``avblocks diagram`` and a sweep's cases
share: :func:`parse_overrides` reads ``--set key=value`` items,
:func:`load_any` turns a target plus overrides into ``(diagram, simulate
kwargs, name, movie options)`` with the scenario's report hooks attached, and
:func:`from_namespace` does that for a Python scenario's names
(``make_diagram(**params)`` or ``diagram``, ``simulation``, ``MOVIE``).
"""

from __future__ import annotations

from pathlib import Path

from ..core.errors import AvError, ScenarioError


def parse_overrides(items):
    """``{key: value}`` from ``--set key=value`` items (values read as YAML,
    so ``3`` is an int and ``[1, 2]`` a list)."""
    import yaml
    out = {}
    for it in items or []:
        if "=" not in it:
            raise ScenarioError(f"--set needs key=value, found '{it}'", entry="--set")
        k, v = it.split("=", 1)
        try:
            out[k.strip()] = yaml.safe_load(v)
        except yaml.YAMLError:
            out[k.strip()] = v
    return out


def from_namespace(ns, overrides, source):
    """(diagram, simulate kwargs, movie options) from a scenario module's
    names: ``make_diagram(**params)`` (returning a Diagram or ``(Diagram,
    simulate_kwargs)``) or ``diagram``, optional ``simulation`` and ``MOVIE``
    dicts. ``--set simulation.<key>=...`` goes to the simulate arguments."""
    from ..core.diagram import Diagram
    sim = dict(ns.get("simulation") or {})
    sim_over = {k.split(".", 1)[1]: v for k, v in overrides.items()
                if k.startswith("simulation.")}
    from ._numeric import resolve, split_overrides
    overrides, numeric = split_overrides(overrides)     # block.param keys
    params = {k: v for k, v in overrides.items() if not k.startswith("simulation.")}
    if "make_diagram" in ns:
        import inspect
        sig = inspect.signature(ns["make_diagram"])
        takes_any = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
        unknown = [k for k in params if k not in sig.parameters and not takes_any]
        if unknown:
            from ..core.errors import did_you_mean
            raise ScenarioError(f"unknown parameter(s) {unknown}", file=source,
                                entry="--set",
                                hint=did_you_mean(unknown[0], sig.parameters)
                                + f"this scenario's parameters: {list(sig.parameters)} "
                                  "(or simulation.t_final, simulation.dt, ...)")
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
        if params:
            raise ScenarioError("this file defines `diagram`, so it takes no --set; "
                                "define make_diagram(**params) instead", file=source)
        d = ns["diagram"]
    else:
        raise ScenarioError("a Python scenario must define make_diagram(**params) or "
                            "a variable `diagram`", file=source)
    if not isinstance(d, Diagram):
        raise ScenarioError("make_diagram()/diagram must be an avblocks.Diagram",
                            file=source, hint=f"found {type(d).__name__}")
    sim.update(sim_over)
    if numeric:
        sim["params"] = {**(sim.get("params") or {}), **resolve(d, numeric, source)}
    return d, sim, dict(ns.get("MOVIE") or {})


class Loaded(tuple):
    """``(diagram, simulate kwargs, name, movie options)``, what
    :func:`load_any` returns, with the scenario's ``hooks`` (its
    ``outcome`` and ``figures``) as an attribute."""

    def __new__(cls, d, sim, name, movie, hooks=None):
        self = super().__new__(cls, (d, sim, name, movie))
        self.hooks = hooks
        return self


def hooks_of(ns, overrides):
    """The scenario's ``outcome`` and ``figures`` hooks from its names."""
    from .report import hooks_from_namespace
    return hooks_from_namespace(ns, overrides)


def load_python(path: Path, overrides):
    """Run a user's Python scenario file (it may import anything it likes)."""
    import runpy
    try:
        ns = runpy.run_path(str(path), run_name="avblocks_scenario")
    except AvError:
        raise
    except Exception as e:  # noqa: BLE001 - the user's file failed
        raise ScenarioError(f"running the file failed: {type(e).__name__}: {e}",
                            file=str(path)) from e
    d, sim, movie = from_namespace(ns, overrides, str(path))
    return Loaded(d, sim, path.stem, movie, hooks_of(ns, overrides))


def load_any(target, overrides, out=None):
    """(diagram, simulate kwargs, name, movie options) from a built-in
    name, a YAML/TOML file or a .py file (``out``: the output folder a
    scenario file's blocks may write to), as a :class:`Loaded` whose
    ``.hooks`` holds the scenario's ``outcome`` and ``figures`` (see
    :mod:`avblocks.scenarios.report`)."""
    import importlib

    from .loader import builtin_scenarios, load_scenario
    p = Path(target)
    builtin = builtin_scenarios()
    if not p.is_file() and target in builtin and builtin[target].suffix == ".py":
        mod = importlib.import_module(f"avblocks.scenarios.{target}")
        d, sim, movie = from_namespace(vars(mod), overrides, target)
        return Loaded(d, sim, target, movie, hooks_of(vars(mod), overrides))
    if p.suffix == ".py":
        if not p.is_file():
            raise ScenarioError("no such file", file=target)
        return load_python(p, overrides)
    sc = load_scenario(target).with_overrides(overrides)
    d, sim = sc.build(output_dir=sc.output_dir(out))
    from .report import hooks_from_data, hooks_from_report
    hooks = hooks_from_data(sc.data.get("outcome"), sc.data.get("figures"), d, sc.source,
                            log=sim.get("log"))
    if sc.data.get("report"):
        from ._report_schema import logged_signals
        hooks = hooks_from_report(sc.data["report"], sc.data.get("parameters") or {}, hooks,
                                  logged_signals(d, sim.get("log"), sc.source), sc.source)
    movie = sc._value(sc.movie_options(), "movie")      # generators too
    return Loaded(d, sim, sc.name, movie, hooks)
