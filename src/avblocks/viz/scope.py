"""Signal plots: :func:`plot_signals`, :func:`plot_trajectories` and the
:class:`Scope` block.

With a few agents :func:`plot_signals` draws one line per agent; with many
it draws the median over agents and the 5-95 % (and 25-75 %) bands, so a
plot of 10,000 agents reads as well as one of 3.

>>> import numpy as np, avblocks as av, avblocks.viz
>>> t = np.linspace(0, 1, 5)
>>> res = av.Results(t, {"c.y": np.ones((5, 3, 2))})
>>> fig = av.viz.plot_signals(res, "c.y")
>>> len(fig.axes)
2
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection, PathCollection, PolyCollection

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.ports import Port
from ..core.results import Results
from .animation import find_pose, is_interactive_backend
from .scene import _indices, obstacle_paths
from .shapes import Drawing
from .shapes import drawing as make_drawing


def _figure(figsize, pyplot=False):
    if pyplot:
        import matplotlib.pyplot as plt
        return plt.figure(figsize=figsize)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def _as_tnk(results, key):
    """Signal as (T, N, K) plus its port spec."""
    a = np.asarray(results[key])
    key = results._key(key)
    p = results.ports.get(key)
    T = a.shape[0]
    agents = p.agents if p is not None else a.ndim >= 2
    if a.ndim == 1:
        a = a.reshape(T, 1, 1)
    elif not agents:
        a = a.reshape(T, 1, -1)
    else:
        a = a.reshape(T, a.shape[1], -1)
    if a.dtype == bool:
        a = a.astype(float)
    return key, a, p


def _comp_names(p, k, key):
    labels = list(p.labels) if p is not None and len(p.labels) == k else \
        ([key.rsplit(".", 1)[-1]] if k == 1 else [f"[{j}]" for j in range(k)])
    units = [u.strip() for u in p.unit.split(",")] if p is not None and p.unit else []
    if len(units) == 1:
        units = units * k
    units = units if len(units) == k else [""] * k
    return [f"{lab} [{u}]" if u else lab for lab, u in zip(labels, units)]


def plot_signals(results, signals, agents=None, *, components=None, max_lines=10,
                 band=(5.0, 95.0), fig=None, figsize=None, title=None):
    """Time plots of logged signals.

    Parameters
    ----------
    results : Results
    signals : str, PortRef or list of them
        Logged signals (``"fleet.pose"``), each (T, N, k), (T, N) or (T,).
    agents : None, int, slice, index list or bool mask
        Agents to show (default: all).
    components : list of int, optional
        Components of the last axis to show (default: all).
    max_lines : int
        Up to this many agents get a line each; more get the median and the
        ``band`` percentiles (plus the 25-75 % band).
    fig : Figure, optional
        Draw into this figure (cleared).

    Returns
    -------
    matplotlib.figure.Figure
        One subplot per signal component, sharing the time axis.
    """
    if isinstance(signals, str) or hasattr(signals, "path"):
        signals = [signals]
    rows = []
    for s in signals:
        key, a, p = _as_tnk(results, s)
        sel = np.arange(a.shape[1]) if agents is None else \
            _indices([agents] if np.isscalar(agents) else agents, a.shape[1], "agents")
        comps = range(a.shape[2]) if components is None else components
        names = _comp_names(p, a.shape[2], key)
        for j in comps:
            rows.append((key, names[j], a[:, sel, j], sel))
    if not rows:
        raise ParameterError("nothing to plot", param="signals", found=signals)
    if fig is None:
        fig = _figure(figsize or (7.0, 1.2 + 1.9 * len(rows)))
    else:
        fig.clear()
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    t = np.asarray(results.t)
    for ax, (key, name, y, sel) in zip(axes, rows):
        if y.shape[1] <= max_lines:
            for i in range(y.shape[1]):
                ax.plot(t, y[:, i], lw=1.2, label=f"agent {sel[i]}")
            if 1 < y.shape[1] <= 10 and ax is axes[0]:
                ax.legend(fontsize=7, ncol=min(5, y.shape[1]), loc="best")
        else:
            lo, q1, med, q3, hi = np.nanpercentile(y, [band[0], 25, 50, 75, band[1]],
                                                   axis=1)
            ax.fill_between(t, lo, hi, color="C0", alpha=0.2, lw=0,
                            label=f"{band[0]:g}-{band[1]:g} %")
            ax.fill_between(t, q1, q3, color="C0", alpha=0.35, lw=0, label="25-75 %")
            ax.plot(t, med, color="C0", lw=1.5, label=f"median of {y.shape[1]}")
            if ax is axes[0]:
                ax.legend(fontsize=7, loc="best")
        ax.set_ylabel(name)
        ax.set_title(key, fontsize=8, loc="left")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_trajectories(results, pose=None, world=None, ax=None, *, agents=None,
                      drawing="arrow", size=None, obstacles=None, title=None,
                      figsize=(6.0, 6.0)):
    """x-y paths of the agents with start (circle) and end (vehicle drawing)
    markers, over the world's obstacles.

    Parameters
    ----------
    results : Results
    pose : str or PortRef, optional
        (T, N, 3) poses, or (T, N, 2) positions (default: first ``*.pose``).
    world, obstacles
        Anything with ``.obstacles``, shapely geometries or vertex arrays.
    ax : Axes, optional
    agents : selection of agents (default: all).
    drawing, size : end marker (see :mod:`avblocks.viz.shapes`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    key = find_pose(results, pose)
    p = np.asarray(results[key], float)
    n = p.shape[1]
    sel = _indices(agents, n, "agents")
    p = p[:, sel]
    if ax is None:
        fig = _figure(figsize)
        ax = fig.add_subplot(1, 1, 1)
    fig = ax.figure
    paths = obstacle_paths(obstacles if obstacles is not None else world)
    if paths:
        ax.add_collection(PathCollection(paths, facecolors="0.55", edgecolors="0.25",
                                         linewidths=0.8, zorder=1))
    k = len(sel)
    cols = _agent_colors(k)
    lc = LineCollection(p[:, :, :2].transpose(1, 0, 2), colors=cols,
                        linewidths=1.3 if k <= 50 else 0.6, zorder=2)
    ax.add_collection(lc)
    ax.scatter(p[0, :, 0], p[0, :, 1], s=22 if k <= 50 else 6, facecolors="white",
               edgecolors=cols, linewidths=1.2, zorder=3, label="start")
    span = np.ptp(p[..., :2].reshape(-1, 2), axis=0).max() if p.size else 1.0
    sz = size if size is not None else 0.04 * max(span, 1e-9)
    if p.shape[2] >= 3:
        d = make_drawing(drawing)
        d = d if isinstance(d, Drawing) else make_drawing("arrow")
        verts = d.place(p[-1], sz)
        fc = np.repeat(cols, d.n_parts, axis=0)
        fc[np.tile(d.fixed, k)] = (0.15, 0.15, 0.15, 1.0)
        ax.add_collection(PolyCollection(verts, facecolors=fc, edgecolors="0.1",
                                         linewidths=0.4, zorder=4))
    else:
        ax.scatter(p[-1, :, 0], p[-1, :, 1], s=22, c=cols, marker="s", zorder=4)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.05)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"{key}: {k} agents, t = {results.t[0]:g}..{results.t[-1]:g} s")
    return fig


def _agent_colors(k):
    import matplotlib as mpl
    if k <= 10:
        return mpl.colormaps["tab10"](np.arange(k))
    return mpl.colormaps["turbo"](np.linspace(0.05, 0.95, k))


class Scope(Block):
    """Record chosen signals while a diagram runs; plot them afterwards (or
    live, with an interactive backend).

    Ports
    -----
    one input per name in ``inputs``, any shape (inherited from the wire).

    Parameters
    ----------
    inputs : str or sequence of str
        Input port names (default ``("u",)``).
    every : int
        Record every ``every``-th major step.
    agents : selection of agents to record (default: all).
    path : str or Path, optional
        Save :meth:`plot` there when the run stops (PNG, SVG, PDF).
    live : bool, optional
        Redraw a window every ``refresh`` records (default: when the
        backend is interactive).
    **plot_options
        Passed to :func:`plot_signals`.

    Example
    -------
    >>> import numpy as np, avblocks as av, avblocks.viz
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Constant(np.ones((2, 2))), name="c")
    >>> s = d.add(av.viz.Scope("cmd"), name="scope")
    >>> d.connect(c.y, s.cmd)
    >>> _ = av.simulate(d, 1.0, dt=0.1)
    >>> s.block.results["cmd"].shape
    (11, 2, 2)
    """

    side_effects = True

    def __init__(self, inputs=("u",), *, every=1, agents=None, path=None, live=None,
                 refresh=20, **plot_options):
        super().__init__()
        self.names = [inputs] if isinstance(inputs, str) else list(inputs)
        for nm in self.names:
            self.declare_input(nm, None, feedthrough=False)
        self.every = max(1, int(every))
        self.agents = agents
        self.path = path
        self.live = live
        self.refresh = max(1, int(refresh))
        from .animation import _check_options
        _check_options(plot_options, plot_signals, "Scope")
        self.plot_options = plot_options
        self._t, self._data = [], {nm: [] for nm in self.names}
        self.fig = None

    def configure(self, inputs):
        self._specs = dict(inputs)      # units and labels of the wired signals

    def on_start(self):
        self._t, self._data = [], {nm: [] for nm in self.names}
        self._k = 0
        self._live = self.live if self.live is not None else is_interactive_backend()

    def on_major_step(self, t, x, u, y):
        k = self._k
        self._k += 1
        if k % self.every:
            return
        self._t.append(float(t))
        for nm in self.names:
            v = np.array(u[nm])
            if self.agents is not None and self.input_ports[nm].agents and v.ndim:
                v = v[_indices(self.agents, v.shape[0], "agents")]
            self._data[nm].append(v)
        if self._live and len(self._t) % self.refresh == 0:
            self._draw_live()

    def _draw_live(self):
        import matplotlib.pyplot as plt
        if self.fig is None:
            self.fig = plt.figure()
        plot_signals(self.results, self.names, fig=self.fig, **self.plot_options)
        self.fig.canvas.draw_idle()
        plt.pause(1e-3)

    def on_stop(self):
        if self.path is not None and self._t:
            self.plot().savefig(self.path, dpi=100)
        if self._live and self._t:
            self._draw_live()

    @property
    def results(self) -> Results:
        """What was recorded, as :class:`~avblocks.Results` keyed by input name."""
        ports = {}
        for nm in self.names:
            p = getattr(self, "_specs", {}).get(nm) or self.input_ports[nm]
            ports[nm] = Port(nm, p.shape, p.dtype, p.unit, p.labels, p.doc, p.agents)
        data = {nm: (np.stack(v) if v else np.zeros((0,))) for nm, v in self._data.items()}
        return Results(np.array(self._t), data, ports)

    def plot(self, **options):
        """:func:`plot_signals` of the recorded signals; returns the Figure."""
        kw = {**self.plot_options, **options}
        return plot_signals(self.results, self.names, **kw)
