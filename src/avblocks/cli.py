"""The ``avblocks`` command.

    avblocks run waypoints --set agents=300 --out out/
    avblocks run my_scenario.yaml
    avblocks run my_diagram.py --set n=50 --set drive.gain=2.0
    avblocks run waypoints --backend jax
    avblocks list [--blocks]
    avblocks diagram waypoints -o diagram.svg
    avblocks sweep formation --grid gain=0.5,1,2 --seeds 20 --out sweep.zarr
    avblocks --version
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .core.errors import AvError, ScenarioError


def _parse_sets(items):
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


def _from_namespace(ns, overrides, source):
    """(diagram, simulate kwargs, movie options) from a scenario module's
    names: ``make_diagram(**params)`` (returning a Diagram or ``(Diagram,
    simulate_kwargs)``) or ``diagram``, optional ``simulation`` and ``MOVIE``
    dicts. ``--set simulation.<key>=...`` goes to the simulate arguments."""
    from .core.diagram import Diagram
    sim = dict(ns.get("simulation") or {})
    sim_over = {k.split(".", 1)[1]: v for k, v in overrides.items()
                if k.startswith("simulation.")}
    from .scenarios._numeric import resolve, split_overrides
    overrides, numeric = split_overrides(overrides)     # block.param keys
    params = {k: v for k, v in overrides.items() if not k.startswith("simulation.")}
    if "make_diagram" in ns:
        import inspect
        sig = inspect.signature(ns["make_diagram"])
        takes_any = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
        unknown = [k for k in params if k not in sig.parameters and not takes_any]
        if unknown:
            from .core.errors import did_you_mean
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


def _hooks(ns, overrides):
    from .scenarios.report import hooks_from_namespace
    return hooks_from_namespace(ns, overrides)


def _load_python(path: Path, overrides):
    """Run a user's Python scenario file (it may import anything it likes)."""
    import runpy
    try:
        ns = runpy.run_path(str(path), run_name="avblocks_scenario")
    except AvError:
        raise
    except Exception as e:  # noqa: BLE001 - the user's file failed
        raise ScenarioError(f"running the file failed: {type(e).__name__}: {e}",
                            file=str(path)) from e
    d, sim, movie = _from_namespace(ns, overrides, str(path))
    return Loaded(d, sim, path.stem, movie, _hooks(ns, overrides))


def load_any(target, overrides, out=None):
    """(diagram, simulate kwargs, name, movie options) from a built-in
    name, a YAML/TOML file or a .py file (``out``: the output folder a
    scenario file's blocks may write to), as a :class:`Loaded` whose
    ``.hooks`` holds the scenario's ``outcome`` and ``figures`` (see
    :mod:`avblocks.scenarios.report`)."""
    import importlib

    from .scenarios import builtin_scenarios, load_scenario
    p = Path(target)
    builtin = builtin_scenarios()
    if not p.is_file() and target in builtin and builtin[target].suffix == ".py":
        mod = importlib.import_module(f"avblocks.scenarios.{target}")
        d, sim, movie = _from_namespace(vars(mod), overrides, target)
        return Loaded(d, sim, target, movie, _hooks(vars(mod), overrides))
    if p.suffix == ".py":
        if not p.is_file():
            raise ScenarioError("no such file", file=target)
        return _load_python(p, overrides)
    sc = load_scenario(target).with_overrides(overrides)
    d, sim = sc.build(output_dir=sc.output_dir(out))
    from .scenarios.report import hooks_from_data, hooks_from_report
    hooks = hooks_from_data(sc.data.get("outcome"), sc.data.get("figures"), d, sc.source)
    if sc.data.get("report"):
        hooks = hooks_from_report(sc.data["report"], sc.data.get("parameters") or {}, hooks)
    movie = sc._value(sc.movie_options(), "movie")      # generators too
    return Loaded(d, sim, sc.name, movie, hooks)


def cmd_run(args):
    # signals, the output folder and atomic writes: see _runio; what the
    # scenario reports (outcome, figures): see scenarios.report
    from ._runio import guarded_run
    return guarded_run(args, load_any)


def _summary(cls) -> str:
    """A class's one-line summary: its docstring's first sentence."""
    para = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
    cut = para.find(". ")
    return para[:cut + 1] if cut >= 0 else para


def cmd_list(args):
    import importlib
    import inspect

    from .scenarios import block_registry, builtin_scenarios, load_scenario
    if args.blocks:
        for k, cls in sorted(block_registry(code_blocks=True).items()):
            print(f"{k:40s} {_summary(cls)}")
        return 0
    for name, path in builtin_scenarios().items():
        if path.suffix == ".py":
            mod = importlib.import_module(f"avblocks.scenarios.{name}")
            desc = (mod.__doc__ or "").strip().split("\n\n")[0]
            sig = inspect.signature(mod.make_diagram)
            params = ", ".join(f"{k}={v.default}" for k, v in sig.parameters.items())
        else:
            sc = load_scenario(name)
            desc = sc.description
            params = ", ".join(f"{k}={v}" for k, v in
                               (sc.data.get("parameters") or {}).items())
        print(f"{name}\n    {' '.join(desc.split())}\n    parameters: {params}")
    return 0


def cmd_diagram(args):
    from .viz.diagram import draw_diagram
    d, _sim, name, _movie = load_any(args.target, _parse_sets(args.set))
    out = args.output or f"{name}-diagram.svg"
    path = draw_diagram(d, out)
    print(f"wrote {path}")
    return 0


def build_parser():
    from . import __version__
    ap = argparse.ArgumentParser(prog="avblocks", description=(
        "Vectorized building blocks for multi-vehicle systems: run scenarios, "
        "list what is there, draw diagrams."))
    ap.add_argument("--version", action="version", version=f"avblocks {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a built-in scenario, a YAML/TOML file or a .py file")
    r.add_argument("target", help="built-in name (see `avblocks list`) or a file")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a parameter (repeatable), e.g. --set agents=300, "
                        "or a block's numeric parameter: --set drive.gain=2.0")
    r.add_argument("--out", help="output folder (default avblocks-out/<name>)")
    r.add_argument("--movie", help="also write a movie (.mp4 or .gif)")
    r.add_argument("--t-final", type=float, dest="t_final", help="simulated time [s]")
    r.add_argument("--realtime", type=float, help="pace to the wall clock (1.0 = real time)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--live", action="store_true",
                   help="draw and steer the run in the browser (prints the URL)")
    r.add_argument("--live-host", default="127.0.0.1",
                   help="interface for --live (default 127.0.0.1 only)")
    r.add_argument("--live-port", type=int, default=0, help="port for --live (0: free)")
    r.add_argument("--backend", choices=("numpy", "jax"),
                   help="engine: numpy (default) or jax (compiled; pure blocks only)")
    r.set_defaults(fn=cmd_run)
    from .interfaces.ros2.cli import add_commands, add_run_options
    add_run_options(r)
    add_commands(sub)
    li = sub.add_parser("list", help="list built-in scenarios (or --blocks)")
    li.add_argument("--blocks", action="store_true", help="list block types instead")
    li.set_defaults(fn=cmd_list)
    dg = sub.add_parser("diagram", help="draw a scenario's diagram (SVG/PNG)")
    dg.add_argument("target")
    dg.add_argument("-o", "--output")
    dg.add_argument("--set", action="append", metavar="KEY=VALUE")
    dg.set_defaults(fn=cmd_diagram)
    from .sweep.cli import add_parser as add_sweep_parser  # `avblocks sweep` (issue 14)
    add_sweep_parser(sub)
    return ap


def main(argv=None):
    os.environ.setdefault("MPLBACKEND", "Agg")
    args = build_parser().parse_args(argv)
    try:
        return args.fn(args)
    except AvError as e:
        print(f"avblocks: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("avblocks: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
