"""The ``avblocks`` command.

    avblocks run waypoints --set agents=300 --out out/
    avblocks run my_scenario.yaml
    avblocks run my_diagram.py --set n=50
    avblocks list [--blocks]
    avblocks diagram waypoints -o diagram.svg
    avblocks --version
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from .core.errors import AvError, ScenarioError, SimulationError


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


def _load_python(path: Path, overrides):
    """A Python file defines ``make_diagram(**params)`` (returning a Diagram or
    ``(Diagram, simulate_kwargs)``) or a module-level ``diagram`` (and an
    optional ``simulation`` dict)."""
    import runpy

    from .core.diagram import Diagram
    try:
        ns = runpy.run_path(str(path), run_name="avblocks_scenario")
    except AvError:
        raise
    except Exception as e:  # noqa: BLE001 - the user's file failed
        raise ScenarioError(f"running the file failed: {type(e).__name__}: {e}",
                            file=str(path)) from e
    sim = dict(ns.get("simulation") or {})
    if "make_diagram" in ns:
        try:
            out = ns["make_diagram"](**overrides)
        except TypeError as e:
            raise ScenarioError(f"make_diagram(): {e}", file=str(path),
                                entry="--set") from None
        if isinstance(out, tuple):
            d, extra = out
            sim.update(extra)
        else:
            d = out
    elif "diagram" in ns:
        if overrides:
            raise ScenarioError("this file defines `diagram`, so it takes no --set; "
                                "define make_diagram(**params) instead", file=str(path))
        d = ns["diagram"]
    else:
        raise ScenarioError("a Python scenario must define make_diagram(**params) or "
                            "a variable `diagram`", file=str(path))
    if not isinstance(d, Diagram):
        raise ScenarioError("make_diagram()/diagram must be an avblocks.Diagram",
                            file=str(path), hint=f"found {type(d).__name__}")
    name = path.stem
    return d, sim, name


def load_any(target, overrides):
    """(diagram, simulate kwargs, name) from a built-in name, YAML/TOML or .py."""
    from .scenarios import builtin_scenarios, load_scenario
    p = Path(target)
    builtin = builtin_scenarios()
    if not p.exists() and target in builtin and builtin[target].suffix == ".py":
        p = builtin[target]
    if p.suffix == ".py":
        if not p.exists():
            raise ScenarioError("no such file", file=target)
        return _load_python(p, overrides)
    sc = load_scenario(target).with_overrides(overrides)
    d, sim = sc.build()
    return d, sim, sc.name


def _trajectory_png(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    try:
        from .viz import plot_trajectories
    except ImportError:
        plot_trajectories = None
    poses = [k for k in res.keys() if k.endswith(".pose") or k.endswith(".position")]
    if not poses:
        return None
    fig, ax = plt.subplots(figsize=(6.5, 6))
    if plot_trajectories is not None:
        plot_trajectories(res, pose=poses[0], ax=ax)
    else:  # pragma: no cover - viz is part of the package
        P = res[poses[0]]
        ax.plot(P[:, :, 0], P[:, :, 1], lw=0.8)
        ax.set_aspect("equal")
    ax.set_title(f"{poses[0]}: {P_shape(res[poses[0]])}, t = 0..{res.t[-1]:g} s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def P_shape(a):
    return f"{a.shape[1]} agents" if a.ndim >= 2 else ""


def cmd_run(args):
    from .core.simulator import simulate
    overrides = _parse_sets(args.set)
    d, sim, name = load_any(args.target, overrides)
    if args.realtime is not None:
        sim["realtime"] = args.realtime
    if args.t_final is not None:
        sim["t_final"] = args.t_final
    sim.setdefault("t_final", 10.0)
    out = Path(args.out or Path("avblocks-out") / name)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    failed = None
    try:
        res = simulate(d, progress=None if not args.quiet else False, **sim)
    except SimulationError as e:
        failed = e
        res = e.results
    except TypeError as e:
        raise ScenarioError(f"bad simulation settings: {e}", entry="simulation") from None
    wall = time.perf_counter() - t0
    files = []
    if res is not None and len(res.t):
        files.append(res.save(out / "results.nc"))
        png = _trajectory_png(res, out / "trajectories.png")
        if png:
            files.append(png)
        if args.movie:
            from .viz import save_movie
            files.append(Path(save_movie(res, args.movie)))
    summary = {
        "scenario": name,
        "agents": res.meta.get("agents") if res is not None else None,
        "simulated_s": float(res.t[-1] - res.t[0]) if res is not None and len(res.t) else 0.0,
        "wall_s": round(wall, 3),
        "realtime_factor": None,
        "files": [str(f) for f in files],
    }
    if summary["simulated_s"] and wall > 0:
        summary["realtime_factor"] = round(summary["simulated_s"] / wall, 1)
    if res is not None and "overruns" in res.meta:
        summary["overruns"] = res.meta["overruns"]
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"scenario      {name}")
    print(f"agents        {summary['agents']}")
    print(f"simulated     {summary['simulated_s']:.3g} s")
    print(f"wall time     {wall:.3g} s")
    if summary["realtime_factor"] is not None:
        print(f"real-time x   {summary['realtime_factor']}")
    for f in files:
        print(f"wrote         {f}")
    if failed is not None:
        print(f"avblocks: error: {failed} (results up to then were saved)", file=sys.stderr)
        return 3
    return 0


def cmd_list(args):
    from .scenarios import block_registry, builtin_scenarios, load_scenario
    if args.blocks:
        for k, cls in sorted(block_registry().items()):
            doc = (cls.__doc__ or "").strip().splitlines()
            print(f"{k:40s} {doc[0] if doc else ''}")
        return 0
    for name, path in builtin_scenarios().items():
        if path.suffix == ".py":
            import importlib
            mod = importlib.import_module(f"avblocks.scenarios.{name}")
            desc = (mod.__doc__ or "").strip().split("\n\n")[0]
            import inspect
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
    d, _sim, name = load_any(args.target, _parse_sets(args.set))
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
                   help="override a parameter (repeatable), e.g. --set agents=300")
    r.add_argument("--out", help="output folder (default avblocks-out/<name>)")
    r.add_argument("--movie", help="also write a movie (.mp4 or .gif)")
    r.add_argument("--t-final", type=float, dest="t_final", help="simulated time [s]")
    r.add_argument("--realtime", type=float, help="pace to the wall clock (1.0 = real time)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(fn=cmd_run)
    li = sub.add_parser("list", help="list built-in scenarios (or --blocks)")
    li.add_argument("--blocks", action="store_true", help="list block types instead")
    li.set_defaults(fn=cmd_list)
    dg = sub.add_parser("diagram", help="draw a scenario's diagram (SVG/PNG)")
    dg.add_argument("target")
    dg.add_argument("-o", "--output")
    dg.add_argument("--set", action="append", metavar="KEY=VALUE")
    dg.set_defaults(fn=cmd_diagram)
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
