"""What a live run records: the logged and drawn signals, their buffers, the Results.

:class:`Recording` is the log half of :class:`~avblocks.viz.live.LiveView`:
it resolves ``log`` and ``plots`` (adding what the page draws: every
``pose``/``position`` output and a 3D position's ``attitude``), sizes the
buffers under ``max_log_bytes`` with the shared run guard's decimation, fills
them at major steps and hands back :class:`~avblocks.core.results.Results`
with the run's metadata (the page's URL without its token, how the run
ended, restarts, parameter changes).
"""

from __future__ import annotations

import math
import time as _time

import numpy as np

from ...core.diagram import PortRef
from ...core.errors import ParameterError
from ...core.results import Results
from ...core.runguard import default_log, log_every_that_fits


class Recording:
    """Log buffers of a :class:`LiveView` (a mix-in: the view holds the
    simulator and the run's settings)."""

    def _setup_log(self, log, plots, max_log_bytes):
        c = self.compiled
        refs = default_log(c) if log is None else (
            [log] if isinstance(log, (str, PortRef)) else list(log))
        self.names, self.aliases, self.specs, self.idx = [], {}, {}, {}

        def add(r):
            i, o = c.resolve(r)
            name = f"{c.names[i]}.{o}"
            alias = r.path if isinstance(r, PortRef) else str(r)
            if alias != name:
                self.aliases[alias] = name
            if name not in self.idx:
                self.names.append(name)
                self.idx[name] = (i, o)
                self.specs[name] = c.blocks[i]._outputs[o]
            return name

        self.logged = [add(r) for r in refs]
        drawn = []
        for n in list(self.names):
            i, o = self.idx[n]
            p = self.specs[n]
            if o in ("pose", "position") and p.shape and len(p.shape) == 2 \
                    and p.shape[1] in (2, 3):
                drawn.append(n)
                if o == "position" and "attitude" in c.blocks[i]._outputs:
                    add(f"{c.names[i]}.attitude")
        # a block with a 3D position and a planar pose (UAVs) is drawn once, in 3D
        in3d = {self.idx[n][0] for n in drawn
                if self.idx[n][1] == "position" and self.specs[n].shape[1] == 3}
        self.drawn = [n for n in drawn
                      if not (self.idx[n][1] == "pose" and self.idx[n][0] in in3d)]
        if plots is None:
            plots = [n for n in self.names if n not in drawn
                     and self.idx[n][1] not in ("attitude", "pose", "position")][:3]
        self.plots = [add(r) for r in plots]
        per = sum(int(np.prod(self.specs[n].shape)) * np.dtype(self.specs[n].dtype).itemsize
                  for n in self.names)
        if self._auto_log and (self.nsteps + 1) * per > max_log_bytes:
            self.log_every = log_every_that_fits(per, self.nsteps, max_log_bytes) or 1
        self.nlog = self.nsteps // self.log_every + 1
        need = self.nlog * per
        if need > max_log_bytes:
            raise ParameterError(
                f"the log would take {need / 1e9:.2f} GB", param="log",
                expected=f"<= {max_log_bytes / 1e9:.2f} GB",
                hint="log fewer signals or decimate with log_every")
        self.bufs = {n: np.empty((self.nlog, *self.specs[n].shape), self.specs[n].dtype)
                     for n in self.names}
        self.tlog = np.empty(self.nlog)
        self.count = 0

    def _record(self):
        sim = self.sim
        if self.count >= self.nlog:
            return
        for n in self.names:
            i, o = self.idx[n]
            self.bufs[n][self.count] = sim.Y[i][o]
        self.tlog[self.count] = sim.t
        self.count += 1

    def _results(self, wall0, snapshot, error=None):
        sim = self.sim
        wall = _time.perf_counter() - wall0
        n = self.count
        start = getattr(self, "_start_values", snapshot)
        changed = {k: v.tolist() for k, v in start.items()
                   if not np.array_equal(v, snapshot[k])}
        meta = {"solver": sim.solver.name, "dt": sim.dt, "seed": self.seed, "t0": sim.t0,
                "t_final": sim.t0 + self.nsteps * sim.dt, "log_every": self.log_every,
                "steps": sim.k, "agents": max([s["n"] for s in self.sources] + [0]),
                "blocks": len(self.compiled.blocks), "wall_time": wall,
                "realtime_factor": (sim.k * sim.dt / wall) if wall > 0 else math.inf,
                "param_changes": list(sim.param_changes),
                "live": {"url": self.url.replace(self.token, "<token>") if self.url else None,
                         "ended_by": self._end, "restarts": self.restarts,
                         "draws": self.draws, "late_resyncs": getattr(self, "late", 0)}}
        if changed:
            meta["params"] = changed
        final = getattr(self, "_final_values", None)
        if final is not None:
            meta["live"]["params_final"] = {k: v.tolist() for k, v in final.items()}
        if self._end in ("interrupted", "page closed", "stop button", "close()"):
            meta["interrupted"] = True
            meta["interrupted_at"] = sim.t
        if error:
            meta["error"] = error
        data = {k: self.bufs[k][:n].copy() for k in self.names}
        return Results(self.tlog[:n].copy(), data, dict(self.specs), meta, self.aliases)
