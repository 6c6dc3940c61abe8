"""3D view for UAVs: :func:`animate3d`.

Positions (T, N, 3) with optional attitudes (T, N, 4) as unit quaternions
(w, x, y, z). Each agent is drawn as its body axes (x red, y green, z blue),
a quadrotor (X arms and four rotor rings in the body x-y plane) or a dot,
with a trail; all agents share one ``Line3DCollection`` per kind of line, and
the body vertices are rotated for all agents in one ``einsum``.

>>> import numpy as np, avblocks as av, avblocks.viz
>>> t = np.linspace(0, 1, 4); p = np.zeros((4, 2, 3)); p[:, 1, 2] = t
>>> a = av.viz.animate3d(av.Results(t, {"uav.position": p}), figsize=(3, 3))
>>> a.render(0).shape
(300, 300, 3)
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ParameterError
from .animation import _Frames, _per_agent, _thin, find_pose, real_time_fps


def quat_to_matrix(q):
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) = (w, x, y, z)
    (body to world)."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _body_lines(kind):
    """Body-frame polylines (L, M, 3) at unit size and their colours."""
    if kind == "axes":
        o = np.zeros(3)
        lines = np.array([[o, [0.6, 0, 0]], [o, [0, 0.6, 0]], [o, [0, 0, 0.6]]])
        return lines, ["tab:red", "tab:green", "tab:blue"]
    if kind == "quadrotor":
        h = 0.5 / np.sqrt(2)
        a = np.linspace(0, 2 * np.pi, 13)
        ring = 0.18 * np.stack([np.cos(a), np.sin(a), 0 * a], -1)
        m = len(a)

        def seg(p, q):
            return np.linspace(p, q, m)
        arms = [seg([-h, -h, 0], [h, h, 0]), seg([-h, h, 0], [h, -h, 0])]
        rotors = [ring + [sx * h, sy * h, 0] for sx, sy in ((1, 1), (1, -1), (-1, 1),
                                                            (-1, -1))]
        nose = [seg([0, 0, 0], [0.35, 0, 0])]
        return np.array(arms + rotors + nose), ["0.2", "0.2", None, None, None, None,
                                                "tab:red"]
    if kind in ("point", "dot", None):
        return np.zeros((0, 2, 3)), []
    raise ParameterError("unknown 3D drawing", param="drawing",
                         expected=["axes", "quadrotor", "point"], found=kind)


class Animation3D(_Frames):
    """A 3D replay; see :func:`animate3d`."""

    def __init__(self, results, position=None, attitude=None, *, every=1, trail=0.0,
                 drawing="quadrotor", size=None, color=None, extent=None, elev=25.0,
                 azim=-60.0, timestamp=True, title=None, figsize=(6.0, 6.0), dpi=100):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.colors import to_rgba, to_rgba_array
        from matplotlib.figure import Figure
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        self.key = find_pose(results, position, suffix=".position")
        p = np.asarray(results[self.key], float)
        if p.ndim != 3 or p.shape[2] < 3:
            raise ParameterError("position must have shape (T, N, 3)", param="position",
                                 expected="(T, N, 3)", found=p.shape)
        self.p = p[..., :3]
        T, n = p.shape[:2]
        self.t = np.asarray(results.t, float)
        self.R = None
        if attitude is not None:
            q = _per_agent(results, attitude, (T, n), "attitude")
            self.R = quat_to_matrix(q)
        self.index = np.arange(0, T, max(1, int(every)))
        self.trail = float(trail or 0.0)
        if extent is None:
            lo = np.nanmin(self.p.reshape(-1, 3), 0)
            hi = np.nanmax(self.p.reshape(-1, 3), 0)
            c, w = (lo + hi) / 2, max(float((hi - lo)[:2].max()), 1.0) * 1.15
            zlo = 0.0 if lo[2] >= 0 else lo[2] - 0.1 * w
            zhi = max(hi[2] + 0.1 * w, zlo + 1.0)
            extent = (c[0] - w / 2, c[0] + w / 2, c[1] - w / 2, c[1] + w / 2, zlo, zhi)
        self.extent = extent
        self.size = float(size) if size is not None else 0.06 * (extent[1] - extent[0])
        self.fig = Figure(figsize=figsize, dpi=dpi)
        FigureCanvasAgg(self.fig)
        ax = self.fig.add_subplot(1, 1, 1, projection="3d")
        self.ax = ax
        ax.view_init(elev=elev, azim=azim)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_zlim(extent[4], extent[5])
        ax.set_box_aspect((extent[1] - extent[0], extent[3] - extent[2],
                           extent[5] - extent[4]))
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        if title:
            ax.set_title(title)
        self.cols = (np.tile(to_rgba(color), (n, 1)) if color is not None
                     else to_rgba_array([f"C{i % 10}" for i in range(n)]))
        self.body, bcols = _body_lines(drawing)
        L = len(self.body)
        per = np.array([to_rgba(c) if c is not None else (0, 0, 0, 0) for c in bcols]
                       ).reshape(L, 4)
        agent_part = np.array([c is None for c in bcols], bool)
        bc = np.repeat(per[None], n, 0)
        bc[:, agent_part] = self.cols[:, None]
        self.body_colors = bc.reshape(n * L, 4)
        self.bodies = Line3DCollection(np.zeros((0, 2, 3)), linewidths=1.6)
        ax.add_collection3d(self.bodies, autolim=False)
        tc = self.cols.copy()
        tc[:, 3] = 0.6
        self.trails = Line3DCollection(np.zeros((0, 2, 3)), colors=tc, linewidths=1.0)
        ax.add_collection3d(self.trails, autolim=False)
        self.dots = ax.scatter(*self.p[0].T, c=self.cols, s=10, depthshade=False)
        self.shadow = Line3DCollection(np.zeros((0, 2, 3)), colors=(0.5, 0.5, 0.5, 0.35),
                                       linewidths=0.8, linestyles="dotted")
        ax.add_collection3d(self.shadow, autolim=False)
        self.stamp = (self.fig.text(0.03, 0.95, "", family="monospace")
                      if timestamp else None)
        dt = float(np.median(np.diff(self.t))) if T > 1 else 0.0
        self.fps_default = real_time_fps(dt, max(1, int(every)))
        self.scene = self      # for _Frames.close

    def __len__(self):
        return len(self.index)

    def update(self, k):
        i = int(self.index[k])
        p = self.p[i]
        n = len(p)
        if len(self.body):
            R = self.R[i] if self.R is not None else np.broadcast_to(np.eye(3), (n, 3, 3))
            w = np.einsum("nij,lmj->nlmi", R, self.body * self.size) + p[:, None, None]
            self.bodies.set_segments(w.reshape(-1, w.shape[2], 3))
            self.bodies.set_color(self.body_colors)
        self.dots._offsets3d = (p[:, 0], p[:, 1], p[:, 2])
        if self.trail > 0:
            j0 = int(np.searchsorted(self.t, self.t[i] - self.trail, side="left"))
            h = _thin(self.p[j0:i + 1])
            self.trails.set_segments(h.transpose(1, 0, 2) if len(h) > 1 else [])
        z0 = self.extent[4]
        self.shadow.set_segments(np.stack([p, np.c_[p[:, :2], np.full(n, z0)]], 1))
        if self.stamp is not None:
            self.stamp.set_text(f"t = {self.t[i]:7.2f} s")

    def render(self, k) -> np.ndarray:
        self.update(k)
        self.fig.canvas.draw()
        return np.array(self.fig.canvas.buffer_rgba())[:, :, :3]

    def close(self):
        import matplotlib.pyplot as plt
        plt.close(self.fig)


def animate3d(results, position=None, attitude=None, **options) -> Animation3D:
    """Replay UAVs in 3D.

    Parameters
    ----------
    results : Results
    position : str or PortRef, optional
        (T, N, 3) positions (default: first logged ``*.position``).
    attitude : str, PortRef or array (T, N, 4), optional
        Unit quaternions (w, x, y, z), body to world; default level.
    every : int
        Draw every ``every``-th sample.
    trail : float
        Trail length in seconds.
    drawing : ``"quadrotor"`` (default), ``"axes"`` or ``"point"``.
    size : float, drawing size in metres (default: 6 % of the view).
    color : one colour for all agents (default: C0, C1... per agent).
    extent : (xmin, xmax, ymin, ymax, zmin, zmax), optional.
    elev, azim : camera angles in degrees.

    Returns
    -------
    Animation3D
        Same movie export as :func:`animate`: ``save(path, fps)``,
        ``to_html5()``, ``render(k)``. Vertical dotted lines drop each agent
        to the floor of the view to help read its height.
    """
    return Animation3D(results, position, attitude, **options)
