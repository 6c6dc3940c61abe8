"""What a scenario shows: its one-line outcome and its figures.

The scenario contract
---------------------
A Python scenario module (or a ``.py`` file run by ``avblocks run``) may
define, next to ``make_diagram(**params)``:

``outcome(res, params) -> (line, numbers)``
    ``line`` is one sentence with numbers ("all 500 informed at 78.7 s");
    ``numbers`` a flat dict of the same figures (JSON-able) for
    ``summary.json``.
``figures(res, out, params) -> list of paths``
    Writes the scenario's figures into the folder ``out`` and returns their
    paths.

``params`` (optional in both) are ``make_diagram``'s arguments as the run
used them (defaults updated with ``--set`` values).

A YAML/TOML scenario declares the same as data, naming built-in metrics
(:data:`METRICS`) and plots (:data:`PLOTS`)::

    outcome:
      - {metric: all_true, signal: drive.done, what: reached all their waypoints}
      - {metric: min_distance, signal: fleet.pose}
    figures:
      - {plot: trajectories, file: waypoints.png, waypoints: drive,
         title: 15 unicycles through random waypoints}
      - {plot: fraction, signal: drive.done, file: done.png}

Without any of these, ``avblocks run`` draws the trajectories of the first
logged pose and reports the run's size.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import AvError, ScenarioError
from ._metrics import METRICS, first_time_all, min_pairwise_distance, plot_fraction  # noqa: F401


def _block_waypoints(diagram, name, entry="figures", source=None):
    blocks = getattr(diagram, "blocks", {}) if diagram is not None else {}
    if name not in blocks:
        raise ScenarioError(f"'waypoints' names no block '{name}'", file=source,
                            entry=entry, hint=f"blocks: {sorted(blocks)}")
    b = blocks[name]
    b = getattr(b, "block", b)
    for attr in ("wps", "waypoints", "goals"):
        if hasattr(b, attr):
            try:
                w = np.asarray(getattr(b, attr), float)
            except (TypeError, ValueError):
                continue
            if w.ndim >= 2 and w.shape[-1] >= 2 and np.all(np.isfinite(w)):
                return w[..., :2]
    raise ScenarioError(f"block '{name}' has no waypoints", file=source, entry=entry)


def _plot_trajectories(res, diagram=None, waypoints=None, obstacles=None, **kw):
    from ..viz import plot_trajectories
    if isinstance(waypoints, str):
        waypoints = _block_waypoints(diagram, waypoints)
    return plot_trajectories(res, waypoints=waypoints, obstacles=obstacles, **kw)


def _plot_signals(res, diagram=None, signals=(), **kw):
    from ..viz import plot_signals
    return plot_signals(res, signals, **kw)


def _plot_fraction(res, diagram=None, **kw):
    return plot_fraction(res, **kw)


#: Built-in plots for scenario files: ``{plot: name, file: x.png, ...args}``.
PLOTS = {"trajectories": _plot_trajectories, "signals": _plot_signals,
         "fraction": _plot_fraction}


def save_figure(fig, path, dpi=110):
    """Save and close a figure; returns the path. The file is written whole
    or not at all (:func:`avblocks.core.atomic.atomic_path`); a failed write
    (a full disk, a read-only folder) is an :class:`AvError` naming the file."""
    import matplotlib.pyplot as plt

    from ..core.atomic import atomic_path, os_reason
    path = Path(path)
    try:
        try:
            fig.tight_layout()
        except Exception:  # noqa: BLE001 - colour bars can refuse; the file is still fine
            pass
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise AvError(f"could not write the figure '{path}': {os_reason(e)}") from None
        import matplotlib as mpl
        fmt = path.suffix.lstrip(".").lower() or mpl.rcParams["savefig.format"]
        with atomic_path(path, hint="the figure was not written") as tmp:
            fig.savefig(tmp, dpi=dpi, format=fmt)
    finally:
        plt.close(fig)
    return path


# ------------------------------------------------------------------ hooks
@dataclass
class Hooks:
    """A scenario's ``outcome(res)`` and ``figures(res, out)`` (either None)."""

    outcome: object = None
    figures: object = None


def _suggest(name, known):
    close = difflib.get_close_matches(str(name), list(known), n=1, cutoff=0.5)
    return f"did you mean '{close[0]}'? " if close else ""


def _n_positional(fn):
    import inspect
    try:
        ps = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return 1
    return sum(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in ps)


def scenario_params(ns, overrides):
    """The parameters a Python scenario runs with: ``make_diagram``'s
    defaults updated with the ``--set`` values."""
    import inspect
    params = {}
    if callable(ns.get("make_diagram")):
        for k, p in inspect.signature(ns["make_diagram"]).parameters.items():
            if p.default is not p.empty:
                params[k] = p.default
    params.update({k: v for k, v in (overrides or {}).items()
                   if not k.startswith("simulation.")})
    return params


def hooks_from_namespace(ns, overrides=None) -> Hooks:
    """The hooks a Python scenario module defines. ``outcome(res)`` or
    ``outcome(res, params)``; ``figures(res, out)`` or
    ``figures(res, out, params)``: ``params`` are the run's parameters."""
    out, figs = ns.get("outcome"), ns.get("figures")
    params = scenario_params(ns, overrides)
    o = f = None
    if callable(out):
        o = (lambda res: out(res, params)) if _n_positional(out) >= 2 else out
    if callable(figs):
        f = (lambda res, d: figs(res, d, params)) if _n_positional(figs) >= 3 else figs
    return Hooks(o, f)


#: Signals each case study's ``outcome``/``figures`` read (``report: nest``
#: in a scenario file): the file must log them.
#: Case studies whose outcome and figures a scenario file can ask for by name
#: (``report: nest``): the ``outcome``/``figures`` of that built-in module.
REPORTS = ("nest", "formation", "flocking", "swap", "honeybee", "pursuit", "spread",
           "navigation", "drone_formation", "uav_tracking")

REPORT_SIGNALS = {
    "nest": ("bees.pose", "gossip.informed"),
    "formation": ("fleet.pose", "lf.error", "supervisor.mode", "collision.hit_obstacle",
                  "collision.hit_agent"),
    "flocking": ("flock.position", "flock.velocity"),
    "swap": ("fleet.position", "drive.done"),
    "honeybee": ("bees.pose", "gossip.informed", "modes.mode"),
    "pursuit": ("pursuers.position", "evader.position", "task.distance"),
    "spread": ("fleet.position", "task.reward", "task.success", "landmarks.y"),
    "navigation": ("fleet.position", "goals.y", "task.success", "task.collision"),
    "drone_formation": ("fleet.position", "ref.position"),
    "uav_tracking": ("target.pose", "uav.position", "uav.attitude", "tracker.found",
                     "tracker.bbox", "follow.estimate", "camera.image"),
}


def hooks_from_report(name, params, base=None, logged=None, source=None) -> Hooks:
    """Hooks of the built-in case study ``name`` (``report: nest`` in a
    scenario file) called with the file's parameters; the file's own
    ``outcome``/``figures`` sections, if any, take precedence. With
    ``logged`` (the names the run will log), a signal the case study reads
    and the file does not log is refused now, naming it."""
    import importlib

    if not isinstance(name, str) or name not in REPORTS:     # a module of ours, by name
        raise ScenarioError(f"unknown report {str(name)!r:.60}", file=source, entry="report",
                            hint=f"reports: {list(REPORTS)}")
    missing = [s for s in REPORT_SIGNALS.get(name, ()) if logged is not None
               and s not in logged]
    if missing:
        raise ScenarioError(f"report '{name}' reads {missing}, which will not be logged",
                            file=source, entry="report",
                            hint=f"log {list(REPORT_SIGNALS[name])} (simulation.log)")
    mod = importlib.import_module(f"avblocks.scenarios.{name}")
    full = scenario_params(vars(mod), {})
    full.update(params)
    h = hooks_from_namespace(vars(mod), {})
    src = f"report: {name}"
    o = (lambda res: _guarded("report", f"the '{name}' outcome", src,
                              mod.outcome, res, full)) if h.outcome else None
    f = (lambda res, out: _guarded("report", f"the '{name}' figures", src,
                                   mod.figures, res, out, full)) if h.figures else None
    base = base or Hooks()
    return Hooks(base.outcome or o, base.figures or f)


def hooks_from_data(outcome_spec, figures_spec, diagram=None, source="<scenario>",
                    log=None, check_log=None):
    """Hooks from a scenario file's ``outcome:`` and ``figures:`` sections,
    checked now, before any simulation (:mod:`._report_schema`): known
    names, arguments and types, figure formats, and, with ``diagram``,
    that every signal named will be logged (``log``: the run's
    ``simulation.log``; None the default log) with a usable shape.
    ``check_log=False`` skips that last check (no diagram to check against).

    A metric or plot that still fails while it runs gives a
    :class:`ScenarioError` naming its entry; a figure that cannot be
    written (a full disk) an :class:`AvError` naming the file."""
    from . import _report_schema as schema
    schema.check_sections(outcome_spec, figures_spec, source)
    outcome_spec = list(outcome_spec or [])
    figures_spec = [dict(f) for f in (figures_spec or [])]
    if check_log is None:
        check_log = diagram is not None
    if check_log:
        logged = schema.logged_signals(diagram, log, source)
        schema.check_logged(outcome_spec, figures_spec, logged, source)
    for i, item in enumerate(figures_spec):    # a block's waypoints: found now
        if isinstance(item.get("waypoints"), str):
            item["waypoints"] = _block_waypoints(diagram, item["waypoints"],
                                                 f"figures[{i}].waypoints", source)

    def outcome(res):
        lines, numbers = [], {}
        for i, item in enumerate(outcome_spec):
            args = {k: v for k, v in item.items() if k != "metric"}
            line, nums = _guarded(f"outcome[{i}]", f"metric '{item['metric']}'", source,
                                  METRICS[item["metric"]], res, **args)
            lines.append(line)
            numbers.update(nums)
        return ", ".join(lines), numbers

    def figures(res, out):
        from .paths import inside
        paths = []
        for i, item in enumerate(figures_spec):
            # a name inside the output folder may still pass through a
            # symbolic link found there (a shared project's avblocks-out/
            # could carry one): resolved, it must stay inside
            inside(item["file"], out, what=f"figures[{i}].file", source=source)
            args = {k: v for k, v in item.items() if k not in ("plot", "file")}
            fig = _guarded(f"figures[{i}]", f"plot '{item['plot']}'", source,
                           PLOTS[item["plot"]], res, diagram=diagram, **args)
            paths.append(save_figure(fig, Path(out) / item["file"]))
        return paths

    return Hooks(outcome if outcome_spec else None, figures if figures_spec else None)


def _guarded(entry, what, source, fn, /, *args, **kwargs):
    """``fn(*args, **kwargs)``; an exception that is not an avblocks error (a
    shape the load-time checks could not foresee) as a ScenarioError naming
    the entry."""
    try:
        return fn(*args, **kwargs)
    except AvError:
        raise
    except (KeyboardInterrupt, MemoryError, OSError):
        raise
    except Exception as e:  # noqa: BLE001 - turned into an error naming the entry
        raise ScenarioError(f"{what} failed: {type(e).__name__}: {e}", file=source,
                            entry=entry) from None


def default_figures(res, out, movie_options=None):
    """The trajectory plot of the first logged pose (or position)."""
    from ..viz import plot_trajectories
    options = movie_options or {}
    keys = [k for k in res.keys() if k.endswith(".pose") or k.endswith(".position")]
    pose = options.get("pose") if options.get("pose") in res else (keys[0] if keys else None)
    if pose is None:
        return []
    fig = _guarded("movie", "the trajectory figure (pose, obstacles)", None,
                   plot_trajectories, res, pose=pose, obstacles=options.get("obstacles"))
    return [save_figure(fig, Path(out) / "trajectories.png")]


def default_outcome(res):
    n = res.meta.get("agents")
    return (f"{n} agents simulated for {float(res.t[-1] - res.t[0]):.3g} s",
            {"agents": n})


def jsonable(o):
    """``o`` with NumPy scalars and arrays as plain Python values, dict keys
    as strings and non-finite floats as None (for ``summary.json``)."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, float) and not np.isfinite(o):
        return None
    return o
