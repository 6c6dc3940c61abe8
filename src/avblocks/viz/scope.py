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
from .animation import find_pose_or_position, is_interactive_backend
from .scene import _indices, obstacle_paths
from .shapes import Drawing
from .shapes import drawing as make_drawing


def _figure(figsize, pyplot=True):
    """A new figure, through pyplot (so ``plt.savefig``, ``plt.show`` and
    notebooks see it, as with any Matplotlib plotting function) unless
    ``pyplot`` is False (then an offscreen Agg figure)."""
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


def _agent_colors(k):
    import matplotlib as mpl
    if k <= 10:
        return mpl.colormaps["tab10"](np.arange(k))
    return mpl.colormaps["turbo"](np.linspace(0.05, 0.95, k))


def _style(k):
    """Line width, line alpha, start-marker size for ``k`` agents."""
    if k <= 20:
        return 1.4, 0.95, 26.0
    if k <= 200:
        return 0.8, 0.7, 10.0
    return 0.45, 0.45, 4.0


def _decimate(t, p, max_points):
    """At most ``max_points`` samples (first and last kept)."""
    T = len(t)
    if max_points is None or T <= max_points:
        return np.arange(T)
    idx = np.unique(np.linspace(0, T - 1, int(max_points)).round().astype(int))
    return idx


def plot_trajectories(results, pose=None, world=None, ax=None, *, agents=None,
                      color=None, cmap="viridis", clim=None, color_labels=None,
                      drawing="arrow", size=None, obstacles=None, waypoints=None,
                      title=None, legend=True, max_points=400, figsize=(6.0, 6.0)):
    """x-y paths of the agents, readable from 3 to thousands of agents.

    Paths are thin and translucent when there are many agents; a white
    circle marks each start and the vehicle drawing (or a square, for
    positions) each end; waypoints are crosses; obstacles are grey.

    Parameters
    ----------
    results : Results
    pose : str or PortRef, optional
        (T, N, 3) poses, or (T, N, 2) positions (default: first ``*.pose``,
        else first ``*.position``).
    world, obstacles
        Anything with ``.obstacles``, shapely geometries or vertex arrays.
    ax : Axes, optional
        Draw there (default: a new pyplot figure, so ``plt.savefig`` works).
    agents : selection of agents (default: all).
    color : None, colour, or a logged signal name (T, N)
        None: one colour per agent. A signal colours each piece of path by
        its value there: bool (e.g. informed: grey then red), int (palette)
        or float (``cmap``, ``clim``, with a colour bar).
    color_labels : (str, str), optional
        Legend names of False / True for a bool signal.
    drawing, size : end marker (see :mod:`avblocks.viz.shapes`).
    waypoints : array (W, 2) or (N, W, 2), optional
        Drawn as crosses.
    title : str, optional
        Default: "<k> agents, t = 0..T s".
    legend : bool
        Legend of the markers (start, end, waypoints, colour values).
    max_points : int
        Samples drawn per path at most (the first and last are kept).

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding ``ax`` (``fig.axes[0]`` when it made one).

    Examples
    --------
    >>> import numpy as np, avblocks as av, avblocks.viz
    >>> t = np.linspace(0, 1, 5)
    >>> pose = np.zeros((5, 2, 3)); pose[:, 1, 0] = t
    >>> fig = av.viz.plot_trajectories(av.Results(t, {"fleet.pose": pose}))
    >>> fig.axes[0].get_xlabel()
    'x [m]'
    """
    import matplotlib as mpl
    from matplotlib.colors import is_color_like, to_rgba, to_rgba_array
    from matplotlib.lines import Line2D

    from .scene import BOOL_COLORS
    key = find_pose_or_position(results, pose)
    p_all = np.asarray(results[key], float)
    if p_all.ndim != 3 or p_all.shape[2] < 2:
        raise ParameterError("positions must have shape (T, N, 2) or (T, N, 3)",
                             param="pose", expected="(T, N, 2|3)", found=p_all.shape)
    t_all = np.asarray(results.t, float)
    n = p_all.shape[1]
    sel = _indices(agents, n, "agents")
    keep = _decimate(t_all, p_all, max_points)
    p = p_all[keep][:, sel]
    k = len(sel)
    if ax is None:
        fig = _figure(figsize)
        ax = fig.add_subplot(1, 1, 1)
    fig = ax.figure
    paths = obstacle_paths(obstacles if obstacles is not None else world)
    if paths:
        ax.add_collection(PathCollection(paths, facecolors="0.6", edgecolors="0.3",
                                         linewidths=0.8, zorder=1))
    lw, alpha, ms = _style(k)
    handles = []
    sig = None
    if isinstance(color, str) and color in results:
        sig = np.asarray(results[color])
        if sig.shape[:2] != p_all.shape[:2]:
            raise ParameterError("colour signal needs one value per sample and agent",
                                 param="color", expected=p_all.shape[:2], found=sig.shape)
        sig = sig.reshape(sig.shape[0], n, -1)[:, :, 0][keep][:, sel]
    elif color is not None and not is_color_like(color):
        raise ParameterError("color is neither a logged signal nor a colour",
                             param="color", expected=f"one of {sorted(results.keys())} "
                             "or a Matplotlib colour", found=color)
    if sig is None:
        cols = (np.tile(to_rgba(color), (k, 1)) if color is not None
                else _agent_colors(k))
        lc_cols = cols.copy()
        lc_cols[:, 3] = alpha
        segs = p[:, :, :2].transpose(1, 0, 2)
        lc = LineCollection(segs, colors=lc_cols, linewidths=lw, zorder=2)
        end_cols = cols
    else:
        # one segment per sample step, coloured by the signal at its start
        a = p[:-1, :, :2]
        b = p[1:, :, :2]
        segs = np.stack([a, b], axis=2).transpose(1, 0, 2, 3).reshape(-1, 2, 2)
        v = sig[:-1].T.reshape(-1)
        if sig.dtype == bool:
            seg_cols = to_rgba_array(BOOL_COLORS)[v.astype(int)]
            end_cols = to_rgba_array(BOOL_COLORS)[sig[-1].astype(int)]
            names = color_labels or (f"{color.rsplit('.', 1)[-1]}: no",
                                     f"{color.rsplit('.', 1)[-1]}: yes")
            handles += [Line2D([], [], color=c, lw=2, label=lab)
                        for c, lab in zip(BOOL_COLORS, names)]
        else:
            lo, hi = clim if clim is not None else (np.nanmin(sig), np.nanmax(sig))
            norm = mpl.colors.Normalize(lo, hi if hi > lo else lo + 1.0)
            cm = mpl.colormaps[cmap] if isinstance(cmap, str) else cmap
            seg_cols = cm(norm(v))
            end_cols = cm(norm(sig[-1]))
            sm = mpl.cm.ScalarMappable(norm=norm, cmap=cm)
            fig.colorbar(sm, ax=ax, shrink=0.8, label=color)
        seg_cols[:, 3] = alpha
        lc = LineCollection(segs, colors=seg_cols, linewidths=lw, zorder=2)
    ax.add_collection(lc)
    ax.scatter(p[0, :, 0], p[0, :, 1], s=ms, facecolors="white",
               edgecolors=end_cols if sig is None else "0.2",
               linewidths=0.8 if k > 20 else 1.2, zorder=3)
    handles.insert(0, Line2D([], [], ls="", marker="o", mfc="white", mec="0.2",
                             label="start"))
    if waypoints is not None:
        w = np.asarray(waypoints, float).reshape(-1, 2)
        many = len(w) > 100
        ax.scatter(w[:, 0], w[:, 1], marker="x", s=4 if many else 18, c="0.15",
                   linewidths=0.5 if many else 0.8, alpha=0.5 if many else 1.0, zorder=3)
        handles.append(Line2D([], [], ls="", marker="x", color="0.15", label="waypoint"))
    span = np.ptp(p[..., :2].reshape(-1, 2), axis=0).max() if p.size else 1.0
    span = max(float(span), 1e-9)
    sz = size if size is not None else span * float(np.clip(0.04 * np.sqrt(20 / max(k, 1)),
                                                            0.008, 0.04))
    if p.shape[2] >= 3:
        d = make_drawing(drawing)
        d = d if isinstance(d, Drawing) else make_drawing("arrow")
        verts = d.place(p[-1], sz)
        fc = np.repeat(end_cols, d.n_parts, axis=0)
        fc[np.tile(d.fixed, k)] = (0.15, 0.15, 0.15, 1.0)
        ax.add_collection(PolyCollection(verts, facecolors=fc, edgecolors="0.1",
                                         linewidths=0.3 if k > 50 else 0.4, zorder=4))
        handles.insert(1, Line2D([], [], ls="", marker=">", mfc="0.5", mec="0.1",
                                 label="end"))
    else:
        ax.scatter(p[-1, :, 0], p[-1, :, 1], s=ms, c=end_cols, marker="s", zorder=4,
                   edgecolors="0.1", linewidths=0.3)
        handles.insert(1, Line2D([], [], ls="", marker="s", mfc="0.5", mec="0.1",
                                 label="end"))
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.05)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(handles=handles, loc="best", fontsize=8, framealpha=0.8)
    ax.set_title(title or f"{k} agents, t = {t_all[0]:g}..{t_all[-1]:g} s")
    return fig

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

    Examples
    --------
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
            import matplotlib.pyplot as plt
            fig = self.plot()
            fig.savefig(self.path, dpi=100)
            plt.close(fig)
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
