"""The 2D scene shared by :func:`animate` and the :class:`Animation2D` block.

A :class:`Scene2D` owns one Matplotlib figure with, per agent group, ONE
:class:`~matplotlib.collections.PolyCollection` for the vehicle drawings and
ONE :class:`~matplotlib.collections.LineCollection` for the trails; a frame
updates them with ``set_verts``/``set_segments`` from vertex arrays computed
for all agents at once, so a frame of 1,000 agents costs a few array
operations plus Matplotlib's own drawing.

>>> import numpy as np
>>> s = Scene2D(2, extent=(-1, 1, -1, 1))
>>> s.update(0.0, np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 1.0]]))
>>> s.render().shape
(600, 600, 3)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.collections import LineCollection, PathCollection, PolyCollection
from matplotlib.colors import to_rgba, to_rgba_array
from matplotlib.path import Path as MplPath

from ..core.errors import ParameterError
from .shapes import Drawing
from .shapes import drawing as make_drawing

#: Colours of False / True for boolean colour signals (e.g. not informed / informed).
BOOL_COLORS = ("0.6", "tab:red")
_DARK = np.array(to_rgba("0.15"))


@dataclass
class Group:
    """A set of agents drawn alike.

    Parameters
    ----------
    agents : None, slice, sequence of int or bool mask
        Which agents (None: all).
    drawing : str, Drawing, (M, 2) array, list of arrays or callable
        See :func:`avblocks.viz.shapes.drawing`.
    size : float, optional
        Length of the drawing in metres (default: 3.5 % of the view).
    color : colour, optional
        Matplotlib colour (default: the ``C0``, ``C1``... cycle by group).
    label : str, optional
        Legend entry.
    """

    agents: object = None
    drawing: object = "arrow"
    size: float | None = None
    color: object = None
    label: str | None = None


def _indices(sel, n, where="groups"):
    if sel is None:
        return np.arange(n)
    if isinstance(sel, slice):
        return np.arange(n)[sel]
    a = np.asarray(sel)
    if a.dtype == bool:
        if a.shape != (n,):
            raise ParameterError("agent mask has the wrong length", param=where,
                                 expected=(n,), found=a.shape)
        return np.flatnonzero(a)
    a = a.astype(int).reshape(-1)
    if a.size and (a.min() < -n or a.max() >= n):
        raise ParameterError("agent index out of range", param=where,
                             expected=f"0..{n - 1}", found=a.tolist())
    return a % n


# ------------------------------------------------------------------ obstacles
def _geoms(obstacles):
    """Flatten ``obstacles`` into shapely geometries or vertex arrays."""
    if obstacles is None:
        return []
    if hasattr(obstacles, "obstacles"):
        return _geoms(obstacles.obstacles)
    if hasattr(obstacles, "geoms") and not hasattr(obstacles, "geom_type"):
        return _geoms(list(obstacles.geoms))       # an environment.World
    if hasattr(obstacles, "geom_type"):
        if hasattr(obstacles, "geoms"):
            return [g for sub in obstacles.geoms for g in _geoms(sub)]
        return [obstacles]
    if isinstance(obstacles, np.ndarray) and obstacles.ndim == 2:
        return [obstacles]
    out = []
    for o in obstacles:
        if hasattr(o, "geom_type") or hasattr(o, "obstacles"):
            out += _geoms(o)
        else:
            a = np.asarray(o, float)
            out += [a] if a.ndim == 2 else list(a)
    return out


def obstacle_paths(obstacles) -> list[MplPath]:
    """Matplotlib paths (holes included) of obstacles given as a world with an
    ``.obstacles`` list, shapely geometries, ``(M, 2)`` vertex arrays or a
    list of any of them."""
    paths = []
    for g in _geoms(obstacles):
        if isinstance(g, np.ndarray):
            paths.append(MplPath(np.vstack([g, g[:1]]), closed=True))
            continue
        gt = g.geom_type
        if gt == "Polygon":
            from shapely.geometry.polygon import orient
            g = orient(g, 1.0)
            rings = [np.asarray(g.exterior.coords)] + [np.asarray(r.coords)
                                                       for r in g.interiors]
            verts = np.vstack(rings)
            codes = np.concatenate([[MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 2)
                                    + [MplPath.CLOSEPOLY] for r in rings])
            paths.append(MplPath(verts[:, :2], codes))
        elif gt in ("LineString", "LinearRing"):
            paths.append(MplPath(np.asarray(g.coords)[:, :2]))
        elif gt == "Point":
            c = np.asarray(g.coords)[0, :2]
            paths.append(MplPath.circle(c, 0.05))
        elif not g.is_empty:
            raise ParameterError("cannot draw this obstacle", param="obstacles",
                                 expected="shapely Polygon or (M, 2) vertices", found=gt)
    return paths


def obstacle_bounds(obstacles):
    """(xmin, xmax, ymin, ymax) of all obstacles, or None."""
    paths = obstacle_paths(obstacles)
    if not paths:
        return None
    v = np.vstack([p.vertices for p in paths])
    return (v[:, 0].min(), v[:, 0].max(), v[:, 1].min(), v[:, 1].max())


def auto_extent(points, *boxes, margin=0.08, min_width=1.0):
    """Square-ish view (xmin, xmax, ymin, ymax) holding ``points`` (..., 2)
    and the given boxes, with a relative margin."""
    pts = [np.asarray(points, float).reshape(-1, 2)] if points is not None else []
    for b in boxes:
        if b is not None:
            pts.append(np.array([[b[0], b[2]], [b[1], b[3]]], float))
    p = np.vstack(pts) if pts else np.zeros((1, 2))
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) == 0:
        p = np.zeros((1, 2))
    lo, hi = p.min(axis=0), p.max(axis=0)
    w = max(float((hi - lo).max()), min_width) * (1 + 2 * margin)
    c = (lo + hi) / 2
    wx = max(w, float(hi[0] - lo[0]) * (1 + 2 * margin))
    wy = max(w, float(hi[1] - lo[1]) * (1 + 2 * margin))
    return (c[0] - wx / 2, c[0] + wx / 2, c[1] - wy / 2, c[1] + wy / 2)


def _load_image(img):
    if isinstance(img, (str, Path)):
        from PIL import Image
        with Image.open(img) as im:
            return np.asarray(im.convert("RGBA"))
    return np.asarray(img)


# ---------------------------------------------------------------------- scene
class Scene2D:
    """A figure with agents, trails, obstacles, background, time stamp.

    Parameters
    ----------
    n : int
        Number of agents.
    groups : list of Group, optional
        Agent groups; default one group of all agents with ``drawing``,
        ``size`` and ``color``.
    drawing, size, color
        Of the default group (see :class:`Group`).
    cmap, clim : colormap and (vmin, vmax) for float colour signals.
    palette : colours for int colour signals (bool: :data:`BOOL_COLORS`).
    obstacles : world with ``.obstacles``, shapely geometries or vertex arrays.
    background : image array (H, W, 3|4) or file path; ``background_extent``
        (xmin, xmax, ymin, ymax) gives its place in the world (default: the
        view extent). Row 0 of the image is the top (largest y).
    extent : (xmin, xmax, ymin, ymax) of the view.
    follow : None, ``"centroid"`` or an agent index: centre the view there at
        every frame, ``follow_width`` metres wide (default: extent width).
    timestamp : bool, show ``t = ... s``.
    collision_color : colour of the ring drawn around colliding agents.
    figsize, dpi : figure size in inches and resolution (600 x 600 pixels
        by default).
    ax : existing Matplotlib axes to draw into.
    pyplot : create the figure through pyplot (for a live window).
    """

    def __init__(self, n, *, groups=None, drawing="arrow", size=None, color=None,
                 cmap="viridis", clim=None, palette=None, obstacles=None,
                 background=None, background_extent=None, extent=None, follow=None,
                 follow_width=None, timestamp=True, title=None, collision_color="red",
                 figsize=(6.0, 6.0), dpi=100, ax=None, pyplot=False, legend=None):
        self.n = int(n)
        self._static_key = None
        self.extent = tuple(float(v) for v in (extent or (-1.0, 1.0, -1.0, 1.0)))
        if ax is None:
            if pyplot:
                import matplotlib.pyplot as plt
                self.fig = plt.figure(figsize=figsize, dpi=dpi)
            else:
                from matplotlib.backends.backend_agg import FigureCanvasAgg
                from matplotlib.figure import Figure
                self.fig = Figure(figsize=figsize, dpi=dpi)
                FigureCanvasAgg(self.fig)
            self.ax = self.fig.add_axes((0.11, 0.08, 0.86, 0.86))
        else:
            self.ax, self.fig = ax, ax.figure
        ax = self.ax
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        if title:
            ax.set_title(title)
        self.cmap = mpl.colormaps[cmap] if isinstance(cmap, str) else cmap
        self.clim = clim
        self.palette = to_rgba_array(palette if palette is not None
                                     else [f"C{i}" for i in range(10)])
        self.follow = follow
        w0 = self.extent[1] - self.extent[0]
        self.follow_width = float(follow_width or w0)
        view = max(w0, self.extent[3] - self.extent[2])
        if follow is not None:
            view = self.follow_width
        if groups is None:
            groups = [Group(None, drawing, size, color)]
        self.groups = []
        self.base = np.zeros((self.n, 4))
        for i, g in enumerate(groups):
            if not isinstance(g, Group):
                g = Group(**g) if isinstance(g, dict) else g
            idx = _indices(g.agents, self.n)
            d = make_drawing(g.drawing)
            sz = float(g.size) if g.size is not None else 0.035 * view
            col = to_rgba(g.color if g.color is not None else f"C{i % 10}")
            self.base[idx] = col
            poly = PolyCollection([], closed=True, edgecolors="0.1", linewidths=0.4,
                                  zorder=3, label=g.label)
            if isinstance(d, Drawing):
                ax.add_collection(poly)
            trail = LineCollection([], linewidths=1.0, zorder=2)
            ax.add_collection(trail)
            self.groups.append({"idx": idx, "drawing": d, "size": sz, "poly": poly,
                                "trail": trail, "color": col, "artist": None})
        self.collision_color = collision_color
        self.halo = PolyCollection([], closed=True, facecolors="none",
                                   edgecolors=collision_color, linewidths=2.0, zorder=4)
        ax.add_collection(self.halo)
        self._ring = np.stack([np.cos(a := np.linspace(0, 2 * np.pi, 24, endpoint=False)),
                               np.sin(a)], -1)
        self._radius = np.zeros(self.n)
        for g in self.groups:
            r = g["drawing"].radius if isinstance(g["drawing"], Drawing) else 0.5
            self._radius[g["idx"]] = 1.15 * r * g["size"]
        paths = obstacle_paths(obstacles)
        self.obstacles = None
        if paths:
            self.obstacles = PathCollection(paths, facecolors="0.45", edgecolors="0.2",
                                            linewidths=0.8, zorder=1)
            ax.add_collection(self.obstacles)
        self.background = None
        if background is not None:
            img = _load_image(background)
            be = background_extent or self.extent
            self.background = ax.imshow(img, extent=tuple(be), origin="upper", zorder=0,
                                        interpolation="bilinear")
        self.timestamp = None
        if timestamp:
            self.timestamp = ax.text(0.02, 0.98, "", transform=ax.transAxes, va="top",
                                     ha="left", zorder=10, fontsize=10, family="monospace",
                                     bbox=dict(facecolor="white", alpha=0.7, lw=0))
        if legend or (legend is None and any(g.label for g in groups)):
            from matplotlib.patches import Patch
            ax.legend(handles=[Patch(color=g["color"], label=gg.label)
                               for g, gg in zip(self.groups, groups) if gg.label],
                      loc="upper right", fontsize=8)
        self.set_view(self.extent)

    # ------------------------------------------------------------------ view
    def set_view(self, extent):
        self._drawn = False
        self.extent = tuple(float(v) for v in extent)
        self.ax.set_xlim(self.extent[0], self.extent[1])
        self.ax.set_ylim(self.extent[2], self.extent[3])

    def _follow(self, pose):
        if self.follow is None:
            return
        if isinstance(self.follow, str):
            c = np.nanmean(pose[:, :2], axis=0)
        else:
            c = pose[int(self.follow), :2]
        h = self.follow_width / 2
        hy = h * (self.extent[3] - self.extent[2]) / max(self.extent[1] - self.extent[0],
                                                         1e-12)
        self.set_view((c[0] - h, c[0] + h, c[1] - hy, c[1] + hy))

    # --------------------------------------------------------------- colours
    def colors(self, values=None) -> np.ndarray:
        """RGBA (N, 4) of the agents: group colours, or ``values`` (N,)
        mapped: bool -> :data:`BOOL_COLORS`, int -> palette, float -> cmap."""
        if values is None:
            return self.base
        v = np.asarray(values).reshape(self.n, -1)[:, 0]
        if v.dtype == bool:
            return to_rgba_array(BOOL_COLORS)[v.astype(int)]
        if v.dtype.kind in "iu":
            return self.palette[v % len(self.palette)]
        lo, hi = self.clim if self.clim is not None else (np.nanmin(v), np.nanmax(v))
        z = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v, dtype=float)
        return self.cmap(np.clip(z, 0.0, 1.0))

    # ---------------------------------------------------------------- update
    def update(self, t, pose, *, trails=None, color=None, collision=None, steer=None):
        """Move everything to a new frame.

        ``pose`` (N, 3); ``trails`` (L, N, 2) past positions, oldest first;
        ``color`` (N,) colour signal; ``collision`` (N,) bool; ``steer`` (N,)
        steering angles for the ``car`` drawing.
        """
        self._drawn = False
        pose = np.asarray(pose, float)
        if pose.shape != (self.n, 3):
            raise ParameterError("pose has the wrong shape", param="pose",
                                 expected=(self.n, 3), found=pose.shape)
        cols = self.colors(color)
        steer = None if steer is None else np.asarray(steer, float).reshape(self.n, -1)[:, -1]
        for g in self.groups:
            idx, d = g["idx"], g["drawing"]
            p = pose[idx]
            if isinstance(d, Drawing):
                verts = d.place(p, g["size"], None if steer is None else steer[idx])
                g["poly"].set_verts(verts, closed=True)
                fc = np.repeat(cols[idx], d.n_parts, axis=0)
                if d.fixed.any():
                    fc[np.tile(d.fixed, len(idx))] = _DARK
                g["poly"].set_facecolor(fc)
            else:
                out = d(p)
                if isinstance(out, np.ndarray):
                    if g["poly"].axes is None:
                        self.ax.add_collection(g["poly"])
                    g["poly"].set_verts(out, closed=True)
                    per = max(1, len(out) // max(len(idx), 1))
                    g["poly"].set_facecolor(np.repeat(cols[idx], per, axis=0))
                else:
                    if g["artist"] is not None and g["artist"] is not out:
                        g["artist"].remove()
                    if out.axes is None:
                        self.ax.add_collection(out)
                    g["artist"] = out
            if trails is not None and len(trails) > 1:
                seg = np.asarray(trails)[:, idx, :2].transpose(1, 0, 2)
                g["trail"].set_segments(seg)
                tc = cols[idx].copy()
                tc[:, 3] *= 0.55
                g["trail"].set_color(tc)
            else:
                g["trail"].set_segments([])
        if collision is not None:
            hit = np.flatnonzero(np.asarray(collision).reshape(self.n, -1)[:, 0])
            rings = (self._ring[None] * self._radius[hit, None, None]
                     + pose[hit, None, :2])
            self.halo.set_verts(rings, closed=True)
        else:
            self.halo.set_verts([])
        if self.timestamp is not None:
            self.timestamp.set_text(f"t = {t:7.2f} s")
        self._follow(pose)

    # ---------------------------------------------------------------- output
    def _dynamic(self):
        arts = []
        for g in self.groups:
            arts += [g["trail"], g["poly"]] + ([g["artist"]] if g["artist"] is not None
                                              else [])
        arts.append(self.halo)
        leg = self.ax.get_legend()
        if leg is not None:
            arts.append(leg)
        if self.timestamp is not None:
            arts.append(self.timestamp)
        return [a for a in arts if a.axes is not None or a is leg]

    def render(self, blit=True) -> np.ndarray:
        """Draw and return the frame as an (H, W, 3) uint8 array.

        With ``blit`` the static part (axes, ticks, background, obstacles)
        is drawn once and reused while the view and figure size stay the
        same; only agents, trails, rings and the time stamp are redrawn.
        """
        canvas = self.fig.canvas
        arts = self._dynamic()
        key = (self.extent, canvas.get_width_height(), len(arts))
        if not blit or self._static_key != key:
            if blit:
                for a in arts:
                    a.set_animated(True)
                canvas.draw()
                self._static = canvas.copy_from_bbox(self.fig.bbox)
                self._static_key = key
                for a in arts:
                    a.set_animated(False)
            else:
                canvas.draw()
        if blit:
            canvas.restore_region(self._static)
            for a in sorted(arts, key=lambda a: a.get_zorder()):
                self.fig.draw_artist(a)
        self._drawn = True
        return np.array(canvas.buffer_rgba())[:, :, :3]

    def pixel(self, x, y) -> tuple[int, int]:
        """(row, column) in :meth:`render`'s image of world point (x, y)."""
        if not getattr(self, "_drawn", False):
            self.fig.canvas.draw()
            self._drawn = True
        h = self.fig.canvas.get_width_height()[1]
        px, py = self.ax.transData.transform((x, y))
        return int(round(h - py)), int(round(px))

    def close(self):
        import matplotlib.pyplot as plt
        plt.close(self.fig)
