"""The live page's controls: run buttons, speed, parameters, scrubbing, restart.

:class:`Controls` is the GUI half of :class:`~avblocks.viz.live.LiveView`:
it builds the viser GUI panel, turns the page's events into commands on the
view's queue, and :meth:`Controls._handle` applies a command in the run
loop's thread (so a parameter change lands between two major steps).
"""

from __future__ import annotations

import math

import numpy as np

from ...core.errors import AvError

#: Speed choices offered in the page (``None``: as fast as possible).
SPEEDS = {"x0.1": 0.1, "x0.2": 0.2, "x0.5": 0.5, "x1": 1.0, "x2": 2.0, "x5": 5.0,
          "x10": 10.0, "max": None}


def _speed_label(speed):
    if speed is None:
        return "max"
    best = min((k for k, v in SPEEDS.items() if v is not None),
               key=lambda k: abs(math.log(SPEEDS[k] / speed)))
    return best



class Controls:
    """GUI and commands of a :class:`LiveView` (a mix-in: the view holds the
    simulator, the log and the server)."""

    def _build_gui(self, uplot):
        gui = self.server.gui
        self._status = gui.add_markdown(self._status_text())
        self._pause_btn = gui.add_button("Pause")
        self._step_btn = gui.add_button("Step")
        self._speed = gui.add_dropdown("Speed", tuple(SPEEDS), initial_value=_speed_label(
            self.speed))
        self._scrub = gui.add_slider("Scrub t [s]", min=self.sim.t0,
                                     max=self.sim.t0 + max(self.nsteps, 1) * self.sim.dt,
                                     step=self.sim.dt * self.log_every,
                                     initial_value=self.sim.t0, disabled=True)
        self._restart_btn = gui.add_button("Restart (new seed)")
        self.estops = [p for p in self.compiled.parameters() if p.rsplit(".", 1)[1] == "estop"]
        self._stop_btn = gui.add_button("Stop (e-stop)" if self.estops else "Stop",
                                        color="red")
        self._pause_btn.on_click(lambda _e: self._cmds.put(("toggle",)))
        self._step_btn.on_click(lambda _e: self._cmds.put(("step",)))
        self._restart_btn.on_click(lambda _e: self._cmds.put(("restart",)))
        self._stop_btn.on_click(lambda _e: self._cmds.put(("stop",)))
        self._speed.on_update(lambda _e: self._cmds.put(("speed", self._speed.value)))
        self._scrub.on_update(lambda _e: self._cmds.put(("scrub", self._scrub.value)))
        self._param_inputs, self._param_kinds = {}, {}
        params = self.compiled.parameters()
        if params:
            with gui.add_folder("Parameters"):
                for path, spec in params.items():
                    h = self._param_input(gui, path, spec)
                    if h is not None:
                        self._param_inputs[path] = h
        self._plot_handles = []
        if self.plots:
            with gui.add_folder("Signals"):
                for n in self.plots:
                    labels = self._plot_labels(n)
                    data = tuple(np.zeros(1) for _ in range(len(labels) + 1))
                    series = (uplot.Series(label="t [s]"),) + tuple(
                        uplot.Series(label=lb, stroke=c, width=1.5)
                        for lb, c in zip(labels, ("#1f77b4", "#d62728", "#2ca02c",
                                                  "#ff7f0e")))
                    self._plot_handles.append(gui.add_uplot(
                        data, series, title=n, aspect=1.8,
                        scales={"x": uplot.Scale(time=False, auto=True)}))

    def _param_input(self, gui, path, spec):
        """One control for a numeric parameter: a slider (both bounds finite)
        or a number field for a scalar, or for an array whose entries are
        all equal (per-agent gains: the value is set for every agent);
        vector fields for other 2/3-vectors; JSON text otherwise."""
        import json
        val = np.asarray(self.sim.get_param(path), float)
        lo, hi = spec.bounds
        lo = None if lo is None or not np.isfinite(lo) else float(lo)
        hi = None if hi is None or not np.isfinite(hi) else float(hi)
        label = path + (f" [{spec.unit}]" if spec.unit else "")
        hint = spec.doc or None
        uniform = val.size >= 1 and np.all(val == val.flat[0]) and np.isfinite(val.flat[0])
        if uniform:
            v = float(val.flat[0])
            if val.size > 1:
                label += " (all)"
                hint = (hint + "; " if hint else "") + f"one value for all {val.size} entries"
            if lo is not None and hi is not None and hi > lo:
                h = gui.add_slider(label, min=lo, max=hi, step=(hi - lo) / 1000,
                                   initial_value=min(max(v, lo), hi), hint=hint)
            else:
                mag = abs(v) if v else 1.0
                h = gui.add_number(label, initial_value=v, min=lo, max=hi,
                                   step=10 ** math.floor(math.log10(mag)) / 100, hint=hint)
            kind = "scalar"
        elif val.size in (2, 3) and np.all(np.isfinite(val)):
            add = gui.add_vector2 if val.size == 2 else gui.add_vector3
            h = add(label, initial_value=tuple(val.ravel().tolist()), hint=hint)
            kind = "vector"
        elif val.size <= 64:
            h = gui.add_text(label, initial_value=json.dumps(val.tolist()), hint=hint)
            kind = "json"
        else:                       # too big to edit in a page (still settable from Python)
            return None
        self._param_kinds[path] = kind
        h.on_update(lambda _e, p=path, hh=h: self._cmds.put(("param", p, hh.value)))
        return h

    def _param_value_for(self, path, cur):
        import json
        kind = self._param_kinds[path]
        if kind == "scalar":
            return float(cur.flat[0])
        if kind == "vector":
            return tuple(cur.ravel().tolist())
        return json.dumps(cur.tolist())

    def _status_text(self):
        sim = self.sim
        t = sim.t if sim.X is not None else sim.t0
        state = ("finished" if sim.k >= self.nsteps else
                 "paused" if getattr(self, "_paused", False) else "running")
        agents = sum(s["n"] for s in self.sources)
        rate = getattr(self, "_draw_rate", 0.0)
        return (f"**t = {t:.2f} s** of {self.sim.t0 + self.nsteps * sim.dt:g} s  \n"
                f"{state} · speed {'max' if self.speed is None else f'x{self.speed:g}'}"
                f" · seed {self.seed}  \n"
                f"{agents} agents · {rate:.0f} draws/s")

    def _notify(self, title, body):
        try:
            self.server.add_notification(title, body, auto_close_seconds=6.0, color="red")
        except Exception:  # noqa: BLE001 - notifications are a courtesy
            pass

    def _handle(self, cmd):
        kind = cmd[0]
        if kind == "toggle":
            self._paused = not self._paused
            if self.server is None:
                return
            self._pause_btn.label = "Resume" if self._paused else "Pause"
            self._scrub.disabled = not self._paused
            if self._paused:
                self._scrub.max = max(self.tlog[max(self.count - 1, 0)], self.sim.t0 + 1e-9)
                self._scrub.value = self._scrub.max
            else:
                self._anchor()
                self._scrubbing = None
        elif kind == "step":
            if not self._paused:
                self._handle(("toggle",))
            self._steps += 1
        elif kind == "pause":
            if self._paused != cmd[1]:
                self._handle(("toggle",))
        elif kind == "speed":
            self.speed = SPEEDS.get(cmd[1], self.speed) if isinstance(cmd[1], str) else cmd[1]
            self._anchor()
        elif kind == "scrub":
            if self._paused and self.count:
                k = int(np.clip(np.searchsorted(self.tlog[: self.count], cmd[1]), 0,
                                self.count - 1))
                self._scrubbing = k
        elif kind == "param":
            path, value = cmd[1], cmd[2]
            try:
                spec = self.compiled.parameters()[path]
                v = np.asarray(value if not isinstance(value, str) else
                               __import__("json").loads(value), float)
                v = np.broadcast_to(v, spec.shape) if v.size == 1 else v.reshape(spec.shape)
                self.sim.set_param(path, v)
            except (AvError, ValueError, TypeError) as e:
                self._notify(f"{path} not changed", str(e))
                h = self._param_inputs.get(path)
                if h is not None:
                    h.value = self._param_value_for(path, np.asarray(self.sim.get_param(path),
                                                                  float))
        elif kind == "restart":
            self._restart()
        elif kind == "stop":
            for p in self.estops:
                self.sim.set_param(p, 1.0)
            if self.estops and self.sim.X is not None:
                self.sim.step()        # the stop value reaches the interfaces
                self._record()
            self._end = "stop button"
        elif kind == "close":
            self._end = cmd[1]
