"""What the live page draws: agents, trails, obstacles and the live plots.

:class:`Drawing` is the scene half of :class:`~avblocks.viz.live.LiveView`
(it reads the view's log buffers and writes viser scene handles): which
outputs are drawn and how (``pose`` as flat arrows, ``position`` as darts or
arrows, points above ``points_above`` agents), the camera framing, a frame
of the log, the trails behind the agents and the uPlot series.
"""

from __future__ import annotations

import math
import time as _time

import numpy as np

from ...core.errors import ParameterError
from . import _scene


class Drawing:
    """Scene and plot drawing of a :class:`LiveView` (a mix-in: the view
    holds the simulator, the log buffers and the viser server)."""

    def _setup_sources(self, colors, agent_size, camera, obstacles):
        from ...environment.world import World
        worlds, seen = [], set()
        extra = obstacles if isinstance(obstacles, (list, tuple)) else \
            ([] if obstacles is None else [obstacles])
        for w in list(extra) + [v for b in self.compiled.blocks for v in vars(b).values()]:
            if isinstance(w, World) and id(w) not in seen:
                seen.add(id(w))
                worlds.append(w)
        for w in extra:
            if not isinstance(w, World):
                raise ParameterError("obstacles must be environment.World objects",
                                     param="obstacles", found=type(w).__name__)
        self.worlds = worlds
        self.sources = []
        first = []
        for k, n in enumerate(self.drawn):
            i, o = self.idx[n]
            shape = self.specs[n].shape
            kind = "pose" if o == "pose" else ("pos3" if shape[1] == 3 else "pos2")
            att = f"{self.compiled.names[i]}.attitude" if kind == "pos3" and \
                f"{self.compiled.names[i]}.attitude" in self.idx else None
            n_agents = shape[0]
            col = _scene.agent_colors(n_agents, colors if k == 0 else None)
            self.sources.append({"name": n, "kind": kind, "att": att, "n": n_agents,
                                 "colors": col,
                                 "points": n_agents > self.points_above})
            first.append(np.asarray(self._initial_value(n), float)[:, :2])
        self.camera = camera or ("3d" if any(s["kind"] == "pos3" for s in self.sources)
                                 else "top")
        if self.camera not in ("top", "3d"):
            raise ParameterError("camera must be 'top' or '3d'", param="camera",
                                 found=camera)
        pts = np.concatenate(first) if first else np.zeros((0, 2))
        self.extent = _scene.frame_extent(pts, worlds)
        span = max(self.extent[1] - self.extent[0], self.extent[3] - self.extent[2])
        if agent_size is None:
            total = max([s["n"] for s in self.sources] + [1])
            agent_size = float(np.clip(span / (1.5 * math.sqrt(total) + 40), 0.05, span / 20))
            if self.camera == "3d":
                agent_size *= 3.0
        self.agent_size = float(agent_size)

    def _initial_value(self, name):
        """A drawn signal at t0, to frame the camera. A diagram with side
        effects (robot interfaces) is not started here (that waits for
        :meth:`run`): zeros then, and the worlds frame the view."""
        i, o = self.idx[name]
        if self.sim.Y is None:
            if self.sim._side:
                return np.zeros(self.specs[name].shape)
            self._init_sim()
        return self.sim.Y[i][o]

    def _add_source(self, s):
        sc = self.server.scene
        name = "/agents/" + s["name"].replace(".", "_")
        P, Q = self._frame(s, None)
        if s["points"]:
            s["handle"] = sc.add_point_cloud(name, P.astype(np.float32), s["colors"],
                                             point_size=self.agent_size,
                                             point_shape="circle", point_shading="flat",
                                             precision="float32")
        else:
            v, f = _scene.ARROW_2D if s["kind"] != "pos3" else _scene.DART_3D
            s["handle"] = sc.add_batched_meshes_simple(
                name, v * self.agent_size, f, batched_wxyzs=Q, batched_positions=P,
                batched_colors=s["colors"], side="double", material="toon3",
                flat_shading=True, cast_shadow=False, receive_shadow=False, lod="off")
        s["trail"] = None

    def _frame(self, s, k):
        """Positions (N, 3) and orientations (N, 4) of a source, live
        (``k`` None) or from log sample ``k``."""
        val = (self.sim.Y[self.idx[s["name"]][0]][self.idx[s["name"]][1]] if k is None
               else self.bufs[s["name"]][k])
        val = np.asarray(val, dtype=float)
        n = val.shape[0]
        P = np.zeros((n, 3))
        P[:, :2] = val[:, :2]
        if s["kind"] == "pose":
            Q = _scene.yaw_quaternions(val[:, 2])
            P[:, 2] = 0.02 * self.agent_size
        elif s["kind"] == "pos3":
            P[:, 2] = val[:, 2]
            if s["att"] is not None:
                a = (self.sim.Y[self.idx[s["att"]][0]][self.idx[s["att"]][1]] if k is None
                     else self.bufs[s["att"]][k])
                Q = np.asarray(a, dtype=float)
            else:
                Q = np.tile([1.0, 0, 0, 0], (n, 1))
        else:
            Q = np.tile([1.0, 0, 0, 0], (n, 1))
            P[:, 2] = 0.02 * self.agent_size
        return P, Q

    def _trails(self, s, k_end):
        """(N * (L-1), 2, 3) trail segments up to log sample ``k_end``."""
        if self.trail <= 0 or k_end < 1:
            return None
        per = self.sim.dt * self.log_every
        L = int(min(k_end + 1, self.trail / per + 1))
        if L < 2:
            return None
        per_agent = min(30, self.trail_segments // s["n"] + 1)     # points per trail
        if per_agent < 2:
            return None
        stride = max(1, math.ceil((L - 1) / (per_agent - 1)))
        ks = np.arange(k_end - (L - 1), k_end + 1)[::-1][::stride][::-1]
        if len(ks) < 2:
            return None
        a = np.asarray(self.bufs[s["name"]][ks], dtype=np.float32)   # (L, N, c)
        pts = np.zeros((len(ks), s["n"], 3), np.float32)
        pts[..., :2] = a[..., :2]
        if s["kind"] == "pos3":
            pts[..., 2] = a[..., 2]
        seg = np.stack([pts[:-1], pts[1:]], axis=2)                 # (L-1, N, 2, 3)
        seg = np.swapaxes(seg, 0, 1).reshape(-1, 2, 3)
        return seg

    def _draw(self, k=None):
        """Send the scene at the live state (``k`` None) or at log sample k."""
        srv = self.server
        kt = self.count - 1 if k is None else k
        now = _time.perf_counter()
        do_trails = now - getattr(self, "_last_trail", 0.0) > 0.5 or k is not None
        with srv.atomic():
            for s in self.sources:
                P, Q = self._frame(s, k)
                h = s["handle"]
                if s["points"]:
                    h.points = P.astype(np.float32)
                else:
                    h.batched_positions = P.astype(np.float32)
                    h.batched_wxyzs = Q.astype(np.float32)
                if do_trails:
                    seg = self._trails(s, kt)
                    if seg is not None and self.trail_style == "dots":
                        # one point cloud: a dot at each trail point but the
                        # newest (under the agent); one node, no instancing
                        pts = np.ascontiguousarray(seg[:, 0, :], dtype=np.float32)
                        cols = np.repeat(s["colors"], len(seg) // s["n"], axis=0)
                        if s["trail"] is None:
                            s["trail"] = srv.scene.add_point_cloud(
                                "/trails/" + s["name"].replace(".", "_"), pts, cols,
                                point_size=0.1 * self.agent_size, point_shape="square",
                                point_shading="flat", precision="float32")
                        else:
                            s["trail"].points = pts
                            if s["trail"].colors.shape != cols.shape:
                                s["trail"].colors = cols
                    elif seg is not None:
                        cols = np.repeat(s["colors"], len(seg) // s["n"], axis=0)
                        cols = np.repeat(cols[:, None, :], 2, axis=1)
                        if s["trail"] is None:
                            s["trail"] = srv.scene.add_line_segments(
                                "/trails/" + s["name"].replace(".", "_"), seg, cols,
                                thickness=2.5, thickness_units="screen")
                        else:
                            s["trail"].points = seg
                            if s["trail"].colors.shape != cols.shape:
                                s["trail"].colors = cols
            if do_trails:
                self._last_trail = now
        self.draws += 1

    def _plot_labels(self, n):
        p = self.specs[n]
        size = int(np.prod(p.shape)) if p.shape else 1
        if p.dtype == bool or np.dtype(p.dtype) == np.bool_:
            return ["count true"] if size > 1 else ["value"]
        if size <= 4:
            return [f"[{j}]" for j in range(size)] if size > 1 else ["value"]
        return ["mean |row|", "max |row|"]

    def _plot_series(self, n, k0, k1):
        a = self.bufs[n][k0:k1]
        m = a.shape[0]
        if a.dtype == np.bool_:
            flat = a.reshape(m, -1)
            return [flat.sum(axis=1).astype(float)] if flat.shape[1] > 1 else \
                [flat[:, 0].astype(float)]
        flat = np.asarray(a, dtype=float).reshape(m, -1)
        if flat.shape[1] <= 4:
            return [flat[:, j] for j in range(flat.shape[1])]
        rows = np.asarray(a, float).reshape(m, a.shape[1] if a.ndim > 1 else 1, -1)
        norms = np.linalg.norm(rows, axis=2)
        return [norms.mean(axis=1), norms.max(axis=1)]

    def _update_plots(self, k_end):
        if not self._plot_handles or k_end < 0:
            return
        per = self.sim.dt * self.log_every
        k0 = max(0, k_end + 1 - int(self.plot_window / per) - 1)
        idx = slice(k0, k_end + 1)
        stride = max(1, (k_end + 1 - k0) // 400)
        t = self.tlog[idx][::stride]
        for n, h in zip(self.plots, self._plot_handles):
            ys = [y[::stride] for y in self._plot_series(n, k0, k_end + 1)]
            h.data = (t, *ys)
