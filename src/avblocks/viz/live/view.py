"""The live view: a run drawn in the browser as it happens, and steered.

:class:`LiveView` owns a :class:`~avblocks.core.simulator.Simulator`, steps
it in its own loop (the caller's thread with :meth:`LiveView.run`, a
background thread with :meth:`LiveView.start`), records what is logged, and
serves a viser page (3D scene and GUI over a websocket, 127.0.0.1 only
unless told otherwise, an unguessable token in the URL) that shows

- every ``pose`` (N, 3) output as flat arrows on the ground plane under a
  top-down camera, every ``position`` (N, 3) output as darts in 3D
  (oriented by the same block's ``attitude`` when it has one), (N, 2)
  positions as arrows without heading; above ``points_above`` agents, as
  points drawn at a lower rate;
- trails (the last ``trail`` seconds of the log), the obstacles and bounds
  of every :class:`~avblocks.environment.World` a block holds;
- a few signals as live plots (uPlot), and the simulated time, speed and
  draw rate;

and lets the user pause / resume / single-step, set the speed (x0.1 ... x10
or as fast as possible), change every numeric parameter
(``compiled.parameters()``; applied at the next major step through
:meth:`Simulator.set_param`, recorded in ``meta["param_changes"]``), scrub
back through the log while paused, restart with a new seed, and stop (which
first sets every parameter named ``estop`` to 1 and takes one more step, so
a robot interface sees the emergency stop before the run ends).

The loop never waits for a browser: with none attached it runs (paced or
not) and returns at ``t_final``. Once a page was attached, the run ends when
the last page closes (after ``close_grace`` seconds), on the Stop button, on
Ctrl-C, or on :meth:`LiveView.close`; at ``t_final`` it holds (scrub and
restart still work) until then. Results come back in every case.
"""

from __future__ import annotations

import math
import queue
import threading
import time as _time

import numpy as np

from ...core.diagram import CompiledDiagram, Diagram
from ...core.errors import ParameterError, SimulationError
from ...core.params import integer
from ...core.runguard import finite_number, whole_steps
from . import _scene
from ._server import LiveViewError, open_server  # noqa: F401  (importable here as before)
from .controls import Controls
from .drawing import Drawing
from .recording import Recording


class LiveView(Recording, Drawing, Controls):
    """Run a diagram live in the browser (see the module docstring).

    Parameters
    ----------
    diagram : Diagram or CompiledDiagram
    t_final, dt, solver, seed, t0, log, log_every, check_finite, x0, params,
    max_log_bytes
        As in :func:`avblocks.simulate`.
    realtime : float or None
        Initial speed: 1.0 is real time (default), ``None`` as fast as
        possible; changed from the page.
    host : str
        Interface to bind, ``"127.0.0.1"`` unless you name another.
    port : int
        0 (default): a free port chosen by the system.
    token : str, optional
        The URL token (default: 32 random URL-safe characters).
    plots : list of ``"block.port"``, optional
        Signals to plot live (default: up to three logged signals that are
        not drawn as agents). Per-agent signals are reduced to the mean and
        max over agents of each agent's norm; small ones plot every element.
    plot_window : float
        Seconds of history in the plots.
    trail : float
        Seconds of trail behind each agent (0: none).
    trail_segments : int
        At most this many trail segments (dots) in all: long trails get
        coarser with more agents, and none are drawn above this many agents.
    trail_style : "dots" or "lines"
        Trails as one point cloud of past positions (default: cheap) or as
        fat screen-space line segments (three.js ``LineSegments2``: in a
        browser without a GPU they cost several times the agents' own
        drawing per frame; see docs/live.md, Speed).
    colors : colour or (N, 3), optional
        Agent colours of the first drawn signal (default: tab10 cycle).
    agent_size : float
        Arrow/dart length in metres (default: from the scene's extent).
    points_above : int
        Draw agents as points (and at ``fps_points``) above this many.
    fps, fps_points : float
        Maximum scene updates per second sent to the page.
    camera : "top" or "3d", optional
        Default: "3d" when a (N, 3) ``position`` is drawn, else "top".
    obstacles : World or list of Worlds, optional
        Worlds to draw besides those the diagram's blocks hold.
    end_on_close : bool
        End the run when the last page closes.
    close_grace : float
        Seconds without a page before that counts as closed (a reload
        reconnects within it).
    hold : bool
        At ``t_final``, keep the page (scrub, restart) while one is open.
    verbose : bool
        Print the URL when the server starts.
    """

    def __init__(self, diagram, t_final=10.0, dt=0.01, solver="rk4", *, seed=0, t0=0.0,
                 log=None, log_every=None, realtime=1.0, check_finite=True, x0=None,
                 params=None, max_log_bytes=2 * 1024**3, host="127.0.0.1", port=0,
                 token=None, plots=None, plot_window=20.0, trail=5.0, colors=None,
                 agent_size=None, points_above=2000, fps=20.0, fps_points=8.0,
                 camera=None, obstacles=None, end_on_close=True, close_grace=2.0,
                 trail_segments=6000, trail_style="dots",
                 hold=True, verbose=True, title=None):
        from ...core.simulator import Simulator
        if isinstance(diagram, Diagram):
            diagram = diagram.build()
        if not isinstance(diagram, CompiledDiagram):
            raise ParameterError("LiveView needs a Diagram", param="diagram",
                                 expected="Diagram", found=type(diagram).__name__)
        self.compiled = diagram
        self._sim_args = dict(dt=dt, solver=solver, t0=t0, check_finite=check_finite, x0=x0)
        self.seed = int(seed)
        self.sim = Simulator(diagram, dt, solver, seed=self.seed, t0=t0,
                             check_finite=check_finite, x0=x0)
        # the shared run guard: the same arguments mean the same as in simulate()
        self.nsteps = whole_steps(self.sim.t0, finite_number(t_final, "t_final"), self.sim.dt)
        self._auto_log = log_every is None     # as simulate(): every step unless too big
        self.log_every = 1 if log_every is None else integer(log_every, None, "log_every",
                                                             lo=1)
        if realtime is not None and not (finite_number(realtime, "realtime") > 0):
            raise ParameterError("realtime factor must be > 0", param="realtime",
                                 expected="> 0 or None", found=realtime)
        self.speed = None if realtime is None else float(realtime)
        self.params = dict(params or {})
        for path, v in self.params.items():     # validate now, set at run()
            i, name = diagram.param_index(path)
            diagram.blocks[i]._params[name].validate(v, diagram.names[i])
        self.host, self.port, self.token = str(host), int(port), token
        self.title = title or "avblocks live"
        self.plot_window, self.trail = float(plot_window), float(trail)
        self.trail_segments = int(trail_segments)
        if trail_style not in ("dots", "lines"):
            raise ParameterError("trail_style must be 'dots' or 'lines'", param="trail_style",
                                 expected="'dots' or 'lines'", found=trail_style)
        self.trail_style = trail_style
        self.points_above = int(points_above)
        self.fps, self.fps_points = float(fps), float(fps_points)
        self.end_on_close, self.close_grace = bool(end_on_close), float(close_grace)
        self.hold, self.verbose = bool(hold), bool(verbose)
        self._setup_log(log, plots, max_log_bytes)
        self._setup_sources(colors, agent_size, camera, obstacles)
        self.server = None
        self.url = None
        self._cmds = queue.Queue()
        self._end = None            # why the run ended, once it has
        self._thread = None
        self._result = None
        self._error = None
        self.restarts = []
        self.draws = 0

    def _init_sim(self):
        self.sim.horizon = self.nsteps
        self.sim.init()
        self.count = 0
        self._record()

    def _start_server(self):
        import viser.uplot as uplot
        if self.sim.X is None:
            self._init_sim()
        srv, self.token = open_server(self.host, self.port, self.token, label=self.title)
        self.server = srv
        self.port = srv.get_port()
        shown = "127.0.0.1" if self.host in ("0.0.0.0", "::", "") else self.host
        self.url = f"http://{shown}:{self.port}/{self.token}/"
        srv.gui.configure_theme(show_share_button=False, control_width="medium")
        sc = srv.scene
        sc.set_up_direction("+z")
        x0, x1, y0, y1 = self.extent
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        half = max(0.5 * (y1 - y0), 0.5 * (x1 - x0) / 1.6)
        fov = math.radians(50.0)
        srv.initial_camera.fov = fov
        if self.camera == "top":
            h = half / math.tan(fov / 2)
            srv.initial_camera.position = (cx, cy - 1e-3 * h, h)
            srv.initial_camera.look_at = (cx, cy, 0.0)
        else:
            r = 2.4 * half / math.tan(fov / 2)
            srv.initial_camera.position = (cx - 0.35 * r, cy - 0.8 * r, 0.6 * r)
            srv.initial_camera.look_at = (cx, cy, 0.0)
        self._cam_height = half / math.tan(fov / 2)
        # viser's default far plane (1000 m) would clip a large scene
        srv.initial_camera.far = max(1000.0, 10.0 * self._cam_height)
        srv.initial_camera.near = max(1e-3, 1e-4 * self._cam_height)
        sc.add_light_ambient("/light/ambient", intensity=0.4)
        # a light grid of plain lines (viser's shader grid costs seconds per
        # frame in software WebGL)
        sc.add_line_segments("/grid", _scene.grid_segments(self.extent), colors=(215, 215, 215),
                             thickness=1.0, thickness_units="screen")
        height = 0.05 * self.agent_size if self.camera == "top" else 1.0
        for j, w in enumerate(self.worlds):
            for m, g in enumerate(w.geoms[: w.n_user]):
                v, f = _scene.prism(g, height)
                sc.add_mesh_simple(f"/world{j}/obstacle{m}", v, f, color=(110, 110, 120),
                                   side="double", material="toon3", flat_shading=True)
                sc.add_line_segments(f"/world{j}/outline{m}", _scene.outline_segments(g, height),
                                     colors=(40, 40, 40), thickness=2.0,
                                     thickness_units="screen")
            if w.bounds is not None:
                bx0, by0, bx1, by1 = w.bounds
                from shapely import box
                sc.add_line_segments(f"/world{j}/bounds",
                                     _scene.outline_segments(box(bx0, by0, bx1, by1), 0.0),
                                     colors=(60, 60, 60), thickness=1.5,
                                     thickness_units="screen")
        for s in self.sources:
            self._add_source(s)
        self._build_gui(uplot)
        srv.on_client_connect(lambda _c: None)

    # -------------------------------------------------------------- loop
    def _restart(self):
        from ...core.simulator import Simulator
        self.sim.close()
        self.restarts.append({"at_t": self.sim.t, "old_seed": self.seed,
                              "param_changes": list(self.sim.param_changes)})
        self.seed += 1
        a = self._sim_args
        self.sim = Simulator(self.compiled, a["dt"], a["solver"], seed=self.seed,
                             t0=a["t0"], check_finite=a["check_finite"], x0=a["x0"])
        self._start_values = {k: np.array(v) for k, v in self.compiled.param_values().items()}
        self._init_sim()
        self._paused = False
        self._pause_btn.label = "Pause"
        self._scrub.disabled = True
        self._scrubbing = None
        self._anchor()

    def _anchor(self):
        self._wall_a = _time.perf_counter()
        self._t_a = self.sim.t

    def _loop(self):
        sim = self.sim
        self._paused, self._steps, self._scrubbing = False, 0, None
        self._had_client, self._last_client = False, 0.0
        if sim.X is None:
            self._init_sim()
        self._anchor()
        last_key = None
        last_draw, last_status, draws0, t_rate = 0.0, 0.0, 0, _time.perf_counter()
        self.late = 0
        while self._end is None:
            while True:
                try:
                    self._handle(self._cmds.get_nowait())
                except queue.Empty:
                    break
                if self._end is not None:
                    return
            sim = self.sim
            now = _time.perf_counter()
            clients = len(self.server.get_clients())
            if clients:
                self._had_client, self._last_client = True, now
            elif self._had_client and self.end_on_close and \
                    now - self._last_client > self.close_grace:
                self._end = "page closed"
                return
            finished = sim.k >= self.nsteps
            if finished and (not self.hold or not clients) and not (
                    self._had_client and self.end_on_close and clients == 0
                    and now - self._last_client <= self.close_grace):
                self._end = "finished"
                if clients:
                    self._draw()
                return
            idle = finished or (self._paused and self._steps == 0)
            if not idle and self.speed is not None:
                due = self._wall_a + (sim.t - self._t_a) / self.speed
                if now < due:
                    idle = True
                elif now - due > 0.25:          # late: do not try to catch up
                    self.late += 1
                    self._anchor()
            if not idle:
                if self._steps:
                    self._steps -= 1
                sim.step()
                if sim.k % self.log_every == 0:
                    self._record()
            fps = self.fps_points if any(s["points"] for s in self.sources) else self.fps
            key = (id(self.sim), self.sim.k, self._scrubbing if self._paused else None,
                   self._paused, self.speed)
            if clients and now - last_draw >= 1.0 / fps and (key != last_key or not idle
                                                             or now - last_draw > 1.0):
                changed, last_key = key != last_key, key
                self._draw(self._scrubbing if self._paused else None)
                last_draw = now
                if now - last_status > 0.25 or (changed and (self._paused or finished)):
                    self._draw_rate = (self.draws - draws0) / max(now - t_rate, 1e-9)
                    draws0, t_rate = self.draws, now
                    self._status.content = self._status_text()
                    self._update_plots(self._scrubbing if (self._paused and
                                                           self._scrubbing is not None)
                                       else self.count - 1)
                    last_status = now
            if idle:
                _time.sleep(0.004 if not (self._paused or finished) else 0.02)

    # ------------------------------------------------------------ public
    def run(self):
        """Serve the page, run to the end (see the module docstring) in this
        thread and return :class:`~avblocks.core.results.Results`."""
        snapshot = {k: np.array(v) for k, v in self.compiled.param_values().items()}
        for path, v in self.params.items():
            self.compiled.set_param(path, v)
        self._start_values = {k: np.array(v) for k, v in self.compiled.param_values().items()}
        wall0 = _time.perf_counter()
        try:
            if self.server is None:
                self._start_server()
            if self.verbose:
                print(f"avblocks live view: {self.url}", flush=True)
            self._loop()
        except KeyboardInterrupt:
            self._end = "interrupted"
        except SimulationError as e:
            self._end = "error"
            e.results = self._results(wall0, snapshot, error=str(e))
            self._result = e.results
            raise
        finally:
            try:
                self.sim.close()
            finally:
                final = {k: np.array(v) for k, v in self.compiled.param_values().items()}
                for k, v in snapshot.items():
                    i, name = self.compiled.param_index(k)
                    self.compiled.blocks[i].__dict__[name] = v
                self._final_values = final
                if self.server is not None:
                    self.server.stop()
        if self._result is None:
            self._result = self._results(wall0, snapshot)
        return self._result

    def start(self):
        """Serve the page and run in a background thread (for notebooks and
        scripts that go on); :meth:`wait` returns the results."""
        if self.server is None:
            self._start_server()
        self._thread = threading.Thread(target=self._run_bg, daemon=True,
                                        name="avblocks-live")
        self._thread.start()
        return self

    def _run_bg(self):
        try:
            self.run()
        except BaseException as e:  # noqa: BLE001 - handed to wait()
            self._error = e

    def wait(self, timeout=None):
        """Results once the run has ended (``None`` if ``timeout`` passed)."""
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                return None
        if self._error is not None:
            raise self._error
        return self._result

    # the page's controls, for scripts and notebooks (thread-safe; they take
    # effect in the run loop, like a click)
    def pause(self):
        """Pause (no-op when paused)."""
        self._cmds.put(("pause", True))

    def resume(self):
        """Resume (no-op when running)."""
        self._cmds.put(("pause", False))

    def step(self):
        """One major step (pauses first)."""
        self._cmds.put(("step",))

    def set_speed(self, speed):
        """Real-time factor (``None``: as fast as possible)."""
        if speed is not None and not float(speed) > 0:
            raise ParameterError("speed must be > 0 or None", param="speed", found=speed)
        self._cmds.put(("speed", speed if speed is None else float(speed)))

    def restart(self):
        """Start again from t0 with the next seed (parameters as they are)."""
        self._cmds.put(("restart",))

    def stop(self):
        """The Stop button: set every ``estop`` parameter to 1, take one
        more step, end the run."""
        self._cmds.put(("stop",))

    def close(self, timeout=10.0):
        """End the run (results saved) and return them."""
        self._cmds.put(("close", "close()"))
        return self.wait(timeout)

    def iframe(self, height=600):
        """An IPython IFrame of the page (for notebooks)."""
        from IPython.display import IFrame
        if self.url is None:
            raise LiveViewError("the view is not serving yet", hint="call start() first")
        return IFrame(self.url, width="100%", height=height)

    def _repr_html_(self):
        if self.url is None:
            return "<i>avblocks LiveView (not started)</i>"
        return (f'<iframe src="{self.url}" width="100%" height="600" '
                f'style="border:0"></iframe>')
