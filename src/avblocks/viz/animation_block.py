""":class:`Animation2D`: drawing the agents while a diagram runs (a side-effect block).

The block twin of :func:`~avblocks.viz.animation.animate`: same scene and
frames, fed by the ``pose`` input at major steps instead of by logged
results, into a window, a movie file or a list of frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from .animation import _check_options, _Frames, _thin, is_interactive_backend, real_time_fps
from .movie import MovieWriter
from .scene import Scene2D, auto_extent, obstacle_bounds


class Animation2D(_Frames, Block):
    """Draw N agents while a diagram runs (a side-effect block).

    With an interactive Matplotlib backend (and ``live`` not False) it draws
    into a window at major steps; otherwise it renders offscreen frames,
    streamed to ``movie`` when given (written on stop) or kept in
    :attr:`frame_list` for :meth:`save` / :meth:`to_html5` after the run.

    Ports
    -----
    pose : in, (N, 3) [m, m, rad]
    color : in, (N,) or (N, 1), only with ``color_input=True``
        bool, int or float colour signal (see :meth:`Scene2D.colors`).
    collision : in, (N,) bool, only with ``collision_input=True``
    steer : in, (N,) or (N, k) [rad], only with ``steer_input=True``
        Steering angle (last component, e.g. an Ackermann ``cmd``).

    Parameters
    ----------
    n : int
        Number of agents.
    every : int
        Draw every ``every``-th major step.
    trail : float
        Trail length in seconds.
    movie : str or Path, optional
        ``.mp4`` or ``.gif`` file written during the run.
    fps : float, optional
        Movie frame rate (default: real time from the step, clipped 1..50).
    live : bool, optional
        Force (True) or forbid (False) a live window; default: when the
        backend is interactive.
    keep_frames : bool, optional
        Keep rendered frames in memory (default: when offscreen without a
        movie file).
    progress : bool, optional
        Progress bar while the movie file is encoded (default: on a terminal).
    extent, world, obstacles, **scene_options
        As for :func:`animate`; without ``extent`` the view fits the first
        poses and the obstacles and grows when agents leave it.

    Examples
    --------
    >>> import numpy as np, avblocks as av, avblocks.viz
    >>> d = av.Diagram()
    >>> f = d.add(av.vehicles.Unicycle(np.zeros((3, 3))), name="fleet")
    >>> c = d.add(av.blocks.Constant(np.ones((3, 2))), name="c")
    >>> a = d.add(av.viz.Animation2D(3, every=5), name="anim")
    >>> d.connect(c.y, f.cmd); d.connect(f.pose, a.pose)
    >>> _ = av.simulate(d, 1.0, dt=0.05)
    >>> len(a.block.frame_list)
    5
    """

    side_effects = True

    def __init__(self, n, *, every=1, trail=0.0, movie=None, fps=None, live=None,
                 keep_frames=None, color_input=False, collision_input=False,
                 steer_input=False, extent=None, world=None, obstacles=None,
                 progress=None, **scene_options):
        Block.__init__(self)
        self.n = int(n)
        self.every = max(1, int(every))
        self.trail = float(trail or 0.0)
        self.movie = None if movie is None else Path(movie)
        self.fps = fps
        self.live = live
        self.keep_frames = keep_frames
        self.extent = extent
        self.obstacles = obstacles if obstacles is not None else world
        _check_options(scene_options, Scene2D, "Animation2D")
        self.scene_options = scene_options
        self.declare_input("pose", (self.n, 3), unit="m, m, rad", feedthrough=False)
        self.inputs_used = ["pose"]
        for flag, name in ((color_input, "color"), (collision_input, "collision"),
                           (steer_input, "steer")):
            if flag:
                self.declare_input(name, None, feedthrough=False)
                self.inputs_used.append(name)
        self.scene = None
        self.frame_list = []
        self.path = None

    # ------------------------------------------------------------ run hooks
    def on_start(self):
        if self.scene is not None:
            self.scene.close()
        self.scene = None
        self.frame_list = []
        self._k = 0
        self._times = []
        self._hist = []
        self._writer = None
        self._pending = None
        self._live = self.live if self.live is not None else is_interactive_backend()
        self._keep = self.keep_frames if self.keep_frames is not None else \
            (self.movie is None and not self._live)
        self.fps_default = self.fps or 20.0

    def _make_scene(self, pose):
        ext = self.extent
        self._auto = ext is None and self.scene_options.get("follow") is None
        if ext is None:
            ext = auto_extent(pose[:, :2], obstacle_bounds(self.obstacles),
                              self.scene_options.get("background_extent"), margin=0.15)
        self.scene = Scene2D(self.n, extent=ext, obstacles=self.obstacles,
                             pyplot=self._live, **self.scene_options)
        if self._live:
            import matplotlib.pyplot as plt
            plt.show(block=False)

    def on_major_step(self, t, x, u, y):
        pose = np.asarray(u["pose"], float)
        k = self._k
        self._k += 1
        if self.trail > 0:
            self._times.append(float(t))
            self._hist.append(pose[:, :2].copy())
            cut = 0
            while t - self._times[cut] > self.trail + 1e-12:
                cut += 1
            if cut:
                del self._times[:cut], self._hist[:cut]
        if k % self.every:
            return
        if self.scene is None:
            self._make_scene(pose)
        s = self.scene
        if self._auto:
            lo, hi = pose[:, :2].min(0), pose[:, :2].max(0)
            e = s.extent
            if lo[0] < e[0] or hi[0] > e[1] or lo[1] < e[2] or hi[1] > e[3]:
                s.set_view(auto_extent(pose[:, :2], e, margin=0.15))
        trails = _thin(np.stack(self._hist)) if self.trail > 0 else None
        s.update(t, pose, trails=trails, color=u.get("color"),
                 collision=u.get("collision"), steer=u.get("steer"))
        if self._live:
            s.fig.canvas.draw_idle()
            s.fig.canvas.flush_events()
            import matplotlib.pyplot as plt
            plt.pause(1e-3)
            if not (self.movie or self._keep):
                return
        frame = s.render()
        if self._keep:
            self.frame_list.append(frame)
        if self.movie is not None:
            self._to_movie(t, frame)

    def _to_movie(self, t, frame):
        if self._writer is None:
            if self.fps is None and self._pending is None:
                self._pending = (t, frame)      # wait for the 2nd frame's time
                return
            fps = self.fps
            if fps is None:
                fps = real_time_fps(t - self._pending[0])
            self.fps_default = fps
            self._writer = MovieWriter(self.movie, fps)
            if self._pending is not None:
                self._writer.append(self._pending[1])
                self._pending = None
        self._writer.append(frame)

    def on_stop(self):
        if self.movie is None:
            return
        if self._writer is None and self._pending is not None:
            self._writer = MovieWriter(self.movie, self.fps or 20.0)
            self._writer.append(self._pending[1])
            self._pending = None
        if self._writer is not None:
            self.path = self._writer.close()
            self._writer = None

    # ------------------------------------------------------- after the run
    def __len__(self):
        return len(self.frame_list)

    def render(self, k):
        return self.frame_list[k]

    def save(self, path, fps=None, *, progress=None, **kw) -> Path:
        """Write the kept frames to a movie file."""
        if not self.frame_list:
            raise ParameterError("no frames kept: run the diagram first (offscreen, or "
                                 "with keep_frames=True)", param="keep_frames")
        return super().save(path, fps, progress=progress, **kw)

    def __repr__(self):
        return Block.__repr__(self)

