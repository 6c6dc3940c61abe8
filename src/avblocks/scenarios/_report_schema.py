"""The schema of a scenario file's ``outcome:`` and ``figures:`` sections.

Every entry is checked when the file is loaded, before anything is built or
simulated (:func:`check_sections`), and again once the diagram is built,
against what the run will log (:func:`check_logged`):

- the metric or plot is a known name (a string, not a mapping);
- each argument is one the metric or plot takes (the names below that are
  also in the Python function's signature, :func:`inspect.signature`), of
  the right type and range: a signal is a ``"block.port"`` string, a title
  a string, a figure size two numbers in ``(0, 50]`` inches, waypoints a
  block name or an ``(W, 2)`` / ``(N, W, 2)`` array of finite numbers ...;
- a figure's ``file`` is a relative name inside the output folder with a
  suffix in :data:`FIGURE_FORMATS`;
- every signal named is logged by the run (``simulation.log``, or the
  default log: every ``pose``/``position`` output), with a shape the metric
  or plot can use (``min_distance`` needs ``(N, >=2)`` positions, a
  ``component`` must exist, agent indices must be below N).

A failure is a :class:`ScenarioError` naming the file, the entry
(``figures[1].figsize``) and what is allowed.
"""

from __future__ import annotations

import math
from pathlib import PurePosixPath, PureWindowsPath

import numpy as np

from ..core.errors import AvError, ScenarioError, did_you_mean

#: Figure file formats a scenario may ask for (by the file's suffix).
FIGURE_FORMATS = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff")
#: Largest figure side [inches] (at the default 110 dpi: 5,500 pixels).
MAX_FIGURE_INCHES = 50.0
#: Longest text (titles, labels) a figure or outcome line takes.
MAX_TEXT = 500


# ------------------------------------------------------------ value checks
# Each check returns None when the value is fine, else what was expected.
def _finite(x):
    return (isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)
            and math.isfinite(float(x)))


def _whole(x):
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)


def signal(v):
    if not (isinstance(v, str) and "." in v.strip(".") and len(v) <= MAX_TEXT
            and not any(c.isspace() for c in v)):
        return "a logged signal 'block.port'"
    return None


def text(v):
    return None if isinstance(v, str) and len(v) <= MAX_TEXT else \
        f"a string (at most {MAX_TEXT} characters)"


def flag(v):
    return None if isinstance(v, bool) else "true or false"


def index(v):
    return None if _whole(v) and 0 <= v < 2**31 else "a whole number >= 0"


def count(lo, hi):
    def check(v):
        return None if _whole(v) and lo <= v <= hi else f"a whole number in [{lo}, {hi}]"
    return check


def positive(v):
    return None if _finite(v) and 0 < v <= 1e6 else "a number > 0"


def pair(lo, hi, increasing=False):
    def check(v):
        ok = (isinstance(v, (list, tuple)) and len(v) == 2 and all(_finite(x) for x in v)
              and all(lo <= x <= hi for x in v) and (not increasing or v[0] < v[1]))
        what = "increasing " if increasing else ""
        return None if ok else f"two {what}numbers in [{lo:g}, {hi:g}]"
    return check


def figsize(v):
    ok = (isinstance(v, (list, tuple)) and len(v) == 2 and all(_finite(x) for x in v)
          and all(0 < x <= MAX_FIGURE_INCHES for x in v))
    return None if ok else f"[width, height] in inches, each in (0, {MAX_FIGURE_INCHES:g}]"


def texts(n):
    def check(v):
        ok = isinstance(v, (list, tuple)) and len(v) == n and all(text(x) is None for x in v)
        return None if ok else f"a list of {n} strings"
    return check


def agents(v):
    if _whole(v) and 0 <= v < 2**31:
        return None
    if (isinstance(v, list) and 0 < len(v) <= 10**6
            and all(_whole(x) and 0 <= x < 2**31 for x in v)):
        return None
    return "an agent index or a list of agent indices (whole numbers >= 0)"


def indices(v):
    ok = (isinstance(v, list) and 0 < len(v) <= 1000
          and all(_whole(x) and 0 <= x < 2**31 for x in v))
    return None if ok else "a list of component indices (whole numbers >= 0)"


def signals(v):
    if isinstance(v, str):
        return signal(v)
    if isinstance(v, list) and 0 < len(v) <= 50 and all(signal(x) is None for x in v):
        return None
    return "a logged signal 'block.port' or a list of them (at most 50)"


def _array(v, shapes, what):
    """v as a finite float array with one of ``shapes`` (None: any size)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return what
    if a.size > 10**6 or not np.all(np.isfinite(a)):
        return what
    for s in shapes:
        if a.ndim == len(s) and all(k is None or k == m for k, m in zip(s, a.shape)):
            if a.size:
                return None
    return what


def waypoints(v):
    if isinstance(v, str):
        return None if v and len(v) <= MAX_TEXT else "a block name"
    return _array(v, [(None, 2), (None, None, 2)],
                  "a block name, or waypoints as a (W, 2) or (N, W, 2) list of numbers")


def obstacles(v):
    what = "a list of obstacles, each a list of [x, y] vertices (at least 3)"
    if not isinstance(v, list) or not v or len(v) > 10**4:
        return what
    for poly in v:
        if _array(poly, [(None, 2)], what) is not None or len(poly) < 3:
            return what
    return None


def color(v):
    if not isinstance(v, str) or len(v) > MAX_TEXT:
        return "a colour name or a logged signal 'block.port'"
    if "." in v.strip(".") and signal(v) is None:
        return None                                   # a signal: checked when logged
    from matplotlib.colors import is_color_like
    return None if is_color_like(v) else "a colour name or a logged signal 'block.port'"


def cmap(v):
    import matplotlib as mpl
    if isinstance(v, str) and v in mpl.colormaps:
        return None
    return "a Matplotlib colour map name, e.g. viridis"


def drawing(v):
    from ..viz.shapes import DRAWINGS
    return None if isinstance(v, str) and v in DRAWINGS else \
        f"one of the drawings {sorted(DRAWINGS)}"


# -------------------------------------------------------------------- schema
#: ``{metric: {argument: check}}``: what an ``outcome:`` entry may hold.
METRIC_ARGS = {
    "all_true": {"signal": signal, "what": text},
    "min_distance": {"signal": signal, "label": text},
    "final_mean": {"signal": signal, "label": text, "unit": text, "component": index},
}
#: ``{plot: {argument: check}}``: what a ``figures:`` entry may hold (besides
#: ``plot`` and ``file``).
PLOT_ARGS = {
    "trajectories": {"pose": signal, "agents": agents, "color": color, "cmap": cmap,
                     "clim": pair(-1e300, 1e300, increasing=True),
                     "color_labels": texts(2), "drawing": drawing, "size": positive,
                     "obstacles": obstacles, "waypoints": waypoints, "title": text,
                     "legend": flag, "max_points": count(2, 100_000),
                     "figsize": figsize},
    "signals": {"signals": signals, "agents": agents, "components": indices,
                "max_lines": count(1, 1000), "band": pair(0, 100, increasing=True),
                "figsize": figsize, "title": text},
    "fraction": {"signal": signal, "label": text, "title": text},
}
REQUIRED = {"all_true": ("signal",), "min_distance": ("signal",),
            "final_mean": ("signal",), "signals": ("signals",), "fraction": ("signal",)}


def _targets():
    """The Python functions the scenario arguments end in (for their signatures)."""
    from ..viz import plot_signals, plot_trajectories
    from . import _metrics as metrics
    return {"all_true": metrics.all_true, "min_distance": metrics.min_distance,
            "final_mean": metrics.final_mean, "trajectories": plot_trajectories,
            "signals": plot_signals, "fraction": metrics.plot_fraction}


def allowed_arguments(name):
    """The arguments a scenario entry for metric/plot ``name`` may set: the
    schema's names that the function's signature takes."""
    import inspect
    schema = {**METRIC_ARGS, **PLOT_ARGS}[name]
    params = inspect.signature(_targets()[name]).parameters
    return {k: c for k, c in schema.items() if k in params}


# --------------------------------------------------------------- load checks
def check_file_name(v, where, source):
    """A figure file: a relative name inside the output folder with a known suffix."""
    if not isinstance(v, str) or not v.strip():
        raise ScenarioError("'file' must be a file name such as trajectories.png",
                            file=source, entry=where, hint=f"found {v!r:.60}")
    posix, win = PurePosixPath(v), PureWindowsPath(v)
    if (posix.is_absolute() or win.is_absolute() or win.drive or ".." in posix.parts
            or ".." in win.parts or v.startswith("~") or len(v) > 255):
        raise ScenarioError(f"'{v:.80}' leaves the output folder", file=source,
                            entry=where, hint="give a name relative to the output folder, "
                                              "e.g. figures/paths.png")
    suffix = posix.suffix.lower()
    if suffix not in FIGURE_FORMATS or posix.stem.strip() == "":
        raise ScenarioError(f"figure file '{v:.80}' has no known format", file=source,
                            entry=where, hint=f"end the name in one of {list(FIGURE_FORMATS)}")


def check_sections(outcome_spec, figures_spec, source="<scenario>"):
    """Check ``outcome:`` and ``figures:`` on their own (load time)."""
    for sec, spec, key, schema in (("outcome", outcome_spec, "metric", METRIC_ARGS),
                                   ("figures", figures_spec, "plot", PLOT_ARGS)):
        if spec is None:
            continue
        if not isinstance(spec, list):
            raise ScenarioError(f"'{sec}' must be a list of {{{key}: ...}} entries",
                                file=source, entry=sec)
        if len(spec) > 100:
            raise ScenarioError(f"'{sec}' has {len(spec)} entries (at most 100)",
                                file=source, entry=sec)
        for i, item in enumerate(spec):
            _check_entry(sec, i, item, key, schema, source)


def _check_entry(sec, i, item, key, schema, source):
    where = f"{sec}[{i}]"
    if not isinstance(item, dict) or key not in item:
        raise ScenarioError(f"each '{sec}' entry needs '{key}'", file=source, entry=where,
                            hint=f"e.g. {{{key}: {next(iter(schema))}, ...}}")
    name = item[key]
    if not isinstance(name, str) or name not in schema:
        shown = name if isinstance(name, str) else repr(name)[:60]
        raise ScenarioError(f"unknown {key} '{shown}'", file=source, entry=f"{where}.{key}",
                            hint=did_you_mean(shown, schema) + f"known: {sorted(schema)}")
    if sec == "figures":
        if "file" not in item:
            raise ScenarioError("each figure needs a 'file' (e.g. trajectories.png)",
                                file=source, entry=where)
        check_file_name(item["file"], f"{where}.file", source)
    allowed = allowed_arguments(name)
    for k, v in item.items():
        if k in (key, "file") and (k == key or sec == "figures"):
            continue
        if not isinstance(k, str) or k not in allowed:
            shown = k if isinstance(k, str) else repr(k)[:60]
            extra = ["file"] if sec == "figures" else []
            raise ScenarioError(f"{key} '{name}' takes no argument '{shown}'", file=source,
                                entry=f"{where}.{shown}",
                                hint=did_you_mean(shown, allowed)
                                + f"'{name}' takes {sorted([*allowed, *extra])}")
        bad = allowed[k](v)
        if bad is not None:
            raise ScenarioError(f"'{k}' must be {bad}", file=source, entry=f"{where}.{k}",
                                hint=f"found {v!r:.80}")
    missing = [k for k in REQUIRED.get(name, ()) if k not in item]
    if missing:
        raise ScenarioError(f"{key} '{name}' needs {missing}", file=source, entry=where,
                            hint=f"e.g. {{{key}: {name}, {missing[0]}: fleet.pose}}")


# ---------------------------------------------------- checks against the log
class Shape(tuple):
    """A logged signal's per-sample shape, with ``agents``: whether its
    first axis is the agent axis."""

    def __new__(cls, shape, agents=True):
        self = super().__new__(cls, tuple(int(k) for k in shape))
        self.agents = bool(agents) and len(self) > 0
        return self

    @property
    def n(self):
        """Agents (1 for a signal without an agent axis)."""
        return self[0] if self.agents else 1

    @property
    def components(self):
        """Values per agent (what :func:`avblocks.viz.plot_signals` draws)."""
        return int(np.prod(self[1:] if self.agents else self))


def logged_signals(diagram, log, source="<scenario>"):
    """``{name: per-sample shape}`` of what a run of ``diagram`` with
    ``simulate(log=log)`` records, aliases (the names a user wrote) included."""
    from ..core.diagram import PortRef
    from ..core.runguard import default_log
    try:
        compiled = diagram.build()
        refs = default_log(compiled) if log is None else (
            [log] if isinstance(log, (str, PortRef)) else list(log))
        out = {}
        for r in refs:
            if not isinstance(r, (str, PortRef)):
                raise ScenarioError("'log' must list 'block.port' names", file=source,
                                    entry="simulation.log", hint=f"found {r!r:.60}")
            i, o = compiled.resolve(r)
            port = compiled.blocks[i]._outputs[o]
            shape = Shape(port.shape, port.agents)
            out[f"{compiled.names[i]}.{o}"] = shape
            out[r.path if isinstance(r, PortRef) else str(r)] = shape
        return out
    except ScenarioError:
        raise
    except AvError as e:
        raise ScenarioError(str(e), file=source, entry="simulation.log") from None
    except TypeError:
        raise ScenarioError("'log' must be a 'block.port' name or a list of them",
                            file=source, entry="simulation.log",
                            hint=f"found {log!r:.60}") from None


def check_logged(outcome_spec, figures_spec, logged, source="<scenario>"):
    """Every signal an entry names is logged, with a shape it can use."""
    def need(sig, where, ndim=None, last_min=None):
        if sig not in logged:
            raise ScenarioError(f"signal '{sig}' will not be logged", file=source,
                                entry=where, hint=did_you_mean(sig, logged)
                                + f"add it to simulation.log; logged: {sorted(logged)}")
        shape = logged[sig]
        if ndim is not None and len(shape) not in ndim:
            raise ScenarioError(f"signal '{sig}' has shape {shape} per sample",
                                file=source, entry=where,
                                hint=f"this entry needs {' or '.join(map(str, ndim))} axes")
        if last_min is not None and (not shape or shape[-1] < last_min):
            raise ScenarioError(f"signal '{sig}' has shape {shape} per sample",
                                file=source, entry=where,
                                hint=f"this entry needs at least {last_min} components "
                                     "on the last axis")
        return shape

    def in_range(vals, n, what, where):
        vals = [vals] if not isinstance(vals, list) else vals
        if any(v >= n for v in vals):
            raise ScenarioError(f"{what} out of range", file=source, entry=where,
                                hint=f"expected 0..{n - 1}, found {vals[:10]}")

    for i, item in enumerate(outcome_spec or []):
        where, m = f"outcome[{i}]", item["metric"]
        if m == "min_distance":
            need(item["signal"], f"{where}.signal", ndim=(2,), last_min=2)
        elif m == "final_mean" and "component" in item:
            shape = need(item["signal"], f"{where}.signal", last_min=1)
            in_range(item["component"], shape[-1], "component", f"{where}.component")
        else:
            need(item["signal"], f"{where}.signal")
    for i, item in enumerate(figures_spec or []):
        where, p = f"figures[{i}]", item["plot"]
        if p == "trajectories":
            pose = item.get("pose")
            if pose is None:
                found = [k for k in logged if k.endswith((".pose", ".position"))]
                if not found:
                    raise ScenarioError("no logged signal ends in '.pose' or '.position'",
                                        file=source, entry=where,
                                        hint=f"name one with 'pose:'; logged: "
                                             f"{sorted(logged)}")
                pose = found[0]
            shape = need(pose, f"{where}.pose", ndim=(2,), last_min=2)
            if "agents" in item:
                in_range(item["agents"], shape[0], "agent index", f"{where}.agents")
            c = item.get("color")
            if isinstance(c, str) and signal(c) is None and "." in c.strip("."):
                cs = need(c, f"{where}.color")
                if cs[:1] != shape[:1] or np.prod(cs) != shape[0]:
                    raise ScenarioError(f"colour signal '{c}' has shape {cs}",
                                        file=source, entry=f"{where}.color",
                                        hint=f"expected one value per agent ({shape[0]},)")
        elif p == "signals":
            sigs = item["signals"] if isinstance(item["signals"], list) else [item["signals"]]
            for s in sigs:
                shape = need(s, f"{where}.signals", ndim=(0, 1, 2))
                if "components" in item:
                    in_range(item["components"], shape.components, "component",
                             f"{where}.components")
                if "agents" in item:
                    in_range(item["agents"], shape.n, "agent index", f"{where}.agents")
        else:
            need(item["signal"], f"{where}.signal")
