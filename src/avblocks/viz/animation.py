"""2D animation: replay a saved run (:func:`animate`, :func:`save_movie`) or
draw while simulating (:class:`Animation2D` block).

Both draw through a :class:`~avblocks.viz.scene.Scene2D` (one collection per
agent group, vectorized vertex transforms), so they stay usable with
thousands of agents.

Example
-------
>>> import numpy as np, avblocks as av, avblocks.viz
>>> t = np.linspace(0, 1, 11)
>>> pose = np.zeros((11, 2, 3)); pose[:, 1, 0] = t
>>> anim = av.viz.animate(av.Results(t, {"fleet.pose": pose}), trail=0.5)
>>> len(anim), anim.render(3).shape
(11, (600, 600, 3))
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.colors import is_color_like

from ..core.errors import ParameterError
from .movie import html5_video, write_movie
from .scene import Scene2D, auto_extent, obstacle_bounds

_MAX_TRAIL_POINTS = 60


def find_pose(results, pose=None, suffix=".pose") -> str:
    """The key of the pose signal: ``pose`` itself, or the first logged
    signal whose name ends in ``suffix``."""
    if pose is not None:
        return results._key(pose)
    for k in results.keys():
        if k.endswith(suffix) or k == suffix.lstrip("."):
            return k
    raise ParameterError(f"no logged signal ends in '{suffix}'; name one", param="pose",
                         expected=f"one of {sorted(results.keys())}", found=None)


def _per_agent(results, spec, shape_tn, name):
    """A (T, N, ...) array from a signal name, PortRef or array (or None)."""
    if spec is None:
        return None
    a = np.asarray(results[spec]) if isinstance(spec, str) or hasattr(spec, "path") \
        else np.asarray(spec)
    if a.shape[:2] != shape_tn:
        raise ParameterError("signal does not have one value per sample and agent",
                             param=name, expected=f"{shape_tn} + (...)", found=a.shape)
    return a


def find_pose_or_position(results, pose=None) -> str:
    """:func:`find_pose`, falling back to the first ``*.position`` signal."""
    try:
        return find_pose(results, pose)
    except ParameterError:
        if pose is not None:
            raise
    try:
        return find_pose(results, None, suffix=".position")
    except ParameterError:
        raise ParameterError("no logged signal ends in '.pose' or '.position'; name one",
                             param="pose", expected=f"one of {sorted(results.keys())}",
                             found=None) from None


def pose_from_positions(p):
    """(T, N, 3) poses from (T, N, 2) positions: the heading is the
    direction of motion (kept while an agent stands still; 0 before it
    first moves)."""
    p = np.asarray(p, float)
    d = np.diff(p, axis=0, prepend=p[:1])
    moving = np.hypot(d[..., 0], d[..., 1]) > 1e-9
    th = np.where(moving, np.arctan2(d[..., 1], d[..., 0]), np.nan)
    if th.shape[0] > 1:
        th[0] = np.where(np.isnan(th[0]), th[1], th[0])
    # forward-fill the heading through samples without motion
    idx = np.where(~np.isnan(th), np.arange(th.shape[0])[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    th = np.nan_to_num(np.take_along_axis(th, idx, axis=0))
    return np.concatenate([p, th[..., None]], axis=2)


def is_interactive_backend() -> bool:
    """True when Matplotlib's backend can open windows."""
    from matplotlib.backends import BackendFilter, backend_registry
    b = mpl.get_backend().lower()
    return b in backend_registry.list_builtin(BackendFilter.INTERACTIVE)


def real_time_fps(dt, every=1, lo=1.0, hi=50.0) -> float:
    """Frame rate that plays samples ``dt`` apart, every ``every``-th, in real
    time, clipped to [lo, hi]."""
    if not (dt and np.isfinite(dt) and dt > 0):
        return 20.0
    return float(np.clip(round(1.0 / (dt * every), 3), lo, hi))


def _thin(hist):
    """At most _MAX_TRAIL_POINTS points of a (L, N, 2) history, keeping the last."""
    step = max(1, math.ceil(len(hist) / _MAX_TRAIL_POINTS))
    return hist[::-1][::step][::-1] if step > 1 else hist


class _Frames:
    """Shared movie export for frame sources (``len`` and ``render(k)``)."""

    fps_default = 20.0

    def frames(self):
        """Iterate over the frames as (H, W, 3) uint8 arrays."""
        for k in range(len(self)):
            yield self.render(k)

    def save(self, path, fps=None, *, progress=None, **kw) -> Path:
        """Write the movie (``.mp4`` through ffmpeg, ``.gif`` through Pillow)."""
        return write_movie(self.frames(), path, fps or self.fps_default, total=len(self),
                           progress=progress, **kw)

    def to_html5(self, fps=None, *, progress=None, embed_limit_mb=40.0) -> str:
        """The movie as an HTML5 ``<video>`` tag (shown inline in notebooks)."""
        return html5_video(self.frames(), fps or self.fps_default, total=len(self),
                           progress=progress, embed_limit_mb=embed_limit_mb)

    def _repr_html_(self):
        return self.to_html5() if len(self) else None

    def close(self):
        """Close the figure."""
        if getattr(self, "scene", None) is not None:
            self.scene.close()


class Animation(_Frames):
    """Replay of a saved run; see :func:`animate` for the parameters.

    Attributes
    ----------
    scene : Scene2D
    index : ndarray of int
        Sample index of each frame.
    """

    def __init__(self, results, pose=None, *, every=1, trail=0.0, color=None,
                 collision=None, steer=None, world=None, obstacles=None, extent=None,
                 **scene_options):
        self.results = results
        self.key = find_pose_or_position(results, pose)
        self.pose = np.asarray(results[self.key], float)
        if self.pose.ndim == 3 and self.pose.shape[2] == 2:
            self.pose = pose_from_positions(self.pose)
        if self.pose.ndim != 3 or self.pose.shape[2] < 3:
            raise ParameterError("pose signal must have shape (T, N, 3)", param="pose",
                                 expected="(T, N, 3)", found=self.pose.shape)
        self.t = np.asarray(results.t, float)
        T, n = self.pose.shape[:2]
        every = int(every)
        if every < 1:
            raise ParameterError("every must be a positive integer", param="every",
                                 expected=">= 1", found=every)
        self.every = every
        self.index = np.arange(0, T, every)
        self.trail = float(trail or 0.0)
        if isinstance(color, str) and color not in results and is_color_like(color):
            scene_options["color"], color = color, None     # a plain colour
        self.color = _per_agent(results, color, (T, n), "color")
        self.collision = _per_agent(results, collision, (T, n), "collision")
        self.steer = _per_agent(results, steer, (T, n), "steer")
        obstacles = obstacles if obstacles is not None else world
        if extent is None:
            extent = auto_extent(self.pose[..., :2], obstacle_bounds(obstacles),
                                 scene_options.get("background_extent"))
        if (self.color is not None and self.color.dtype.kind == "f"
                and scene_options.get("clim") is None):
            scene_options["clim"] = (float(np.nanmin(self.color)),
                                     float(np.nanmax(self.color)))
        self.scene = Scene2D(n, obstacles=obstacles, extent=extent, **scene_options)
        dt = float(np.median(np.diff(self.t))) if T > 1 else 0.0
        self.fps_default = real_time_fps(dt, every)

    def __len__(self):
        return len(self.index)

    def update(self, k):
        """Move the scene to frame ``k`` (without drawing)."""
        i = int(self.index[k])
        trails = None
        if self.trail > 0:
            j0 = int(np.searchsorted(self.t, self.t[i] - self.trail, side="left"))
            trails = _thin(self.pose[j0:i + 1, :, :2])

        def pick(a):
            return None if a is None else a[i]

        self.scene.update(self.t[i], self.pose[i], trails=trails, color=pick(self.color),
                          collision=pick(self.collision), steer=pick(self.steer))

    def render(self, k) -> np.ndarray:
        """Frame ``k`` as an (H, W, 3) uint8 array."""
        self.update(k)
        return self.scene.render()

    def show(self, fps=None):
        """Play in a window (needs an interactive Matplotlib backend and the
        animation made with ``pyplot=True``); returns the FuncAnimation."""
        import matplotlib.pyplot as plt
        from matplotlib.animation import FuncAnimation
        fa = FuncAnimation(self.scene.fig, lambda k: self.update(k), frames=len(self),
                           interval=1000.0 / (fps or self.fps_default))
        plt.show()
        return fa


def animate(results, pose=None, **options) -> Animation:
    """Replay a run in 2D.

    Parameters
    ----------
    results : Results
    pose : str or PortRef, optional
        The (T, N, 3) pose signal (default: the first logged ``*.pose``).
    every : int
        Frame decimation: draw every ``every``-th sample.
    trail : float
        Trail length in seconds (0: none, ``inf``: whole path).
    color : str or array (T, N)
        Colour agents by a signal: bool (e.g. informed), int (a palette
        index) or float (mapped through ``cmap``/``clim``); a plain
        Matplotlib colour name that is not a logged signal colours all.
    collision : str or array (T, N) bool
        Draw a ring around colliding agents.
    steer : str or array (T, N) or (T, N, k)
        Steering angle for the ``car`` drawing (last component).
    world, obstacles
        Anything with an ``.obstacles`` list, shapely geometries or vertex
        arrays.
    extent : (xmin, xmax, ymin, ymax), optional
        Fixed view (default: fits the whole run and the obstacles).
    **options
        Drawing options of :class:`~avblocks.viz.scene.Scene2D`: ``groups``,
        ``drawing``, ``size``, ``color`` per group, ``cmap``, ``clim``,
        ``background``, ``background_extent``, ``follow``, ``follow_width``,
        ``timestamp``, ``figsize``, ``dpi``...

    Returns
    -------
    Animation
        ``len(anim)`` frames; ``anim.render(k)``, ``anim.save(path, fps)``,
        ``anim.to_html5()``; shows inline in a notebook.
    """
    return Animation(results, pose, **options)


def plot_frame(results, t=None, pose=None, ax=None, *, figsize=(6.0, 6.0), **options):
    """One frame of :func:`animate` as a still plot: the agents at time ``t``
    (default: the last sample), drawn into ``ax`` (default: a new pyplot
    figure, so ``plt.savefig`` works).

    ``options`` are those of :func:`animate` (``color``, ``trail``,
    ``obstacles``, ``title``, ``drawing``, ``size``...). Returns the Figure.

    >>> import numpy as np, avblocks as av, avblocks.viz
    >>> t = np.linspace(0, 1, 5)
    >>> pose = np.zeros((5, 2, 3)); pose[:, 1, 0] = t
    >>> fig = av.viz.plot_frame(av.Results(t, {"fleet.pose": pose}), t=0.5)
    >>> fig.axes[0].texts[0].get_text()
    't =    0.50 s'
    """
    if ax is None:
        import matplotlib.pyplot as plt
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(1, 1, 1)
    anim = Animation(results, pose, ax=ax, **options)
    ts = np.asarray(results.t, float)
    k = len(ts) - 1 if t is None else int(np.argmin(np.abs(ts - float(t))))
    anim.update(k)
    return ax.figure


def _check_options(options, target, block):
    """Unknown drawing options fail at construction, not at the first frame."""
    import inspect

    from ..core.errors import ParameterError
    known = set(inspect.signature(target).parameters)
    bad = sorted(set(options) - known)
    if bad:
        raise TypeError(str(ParameterError(
            f"unknown option(s) {bad}", block=block,
            expected=f"one of {sorted(known - {'self', 'n'})}")))


#: GIF defaults of :func:`save_movie`: at most this many frames, this frame
#: rate at most, this resolution (dots per inch of the 6-inch figure).
GIF_MAX_FRAMES, GIF_FPS, GIF_DPI = 200, 10.0, 60


def save_movie(results, path, pose=None, fps=None, every=None, *, progress=None,
               **options) -> Path:
    """Write a movie of a run to ``path`` (``.mp4`` or ``.gif``).

    ``pose`` defaults to the first logged signal ending in ``.pose``;
    ``options`` are those of :func:`animate` (``color=`` a logged signal,
    ``title=``, ``trail=``, ``obstacles=``...).

    Frame rate and decimation: for MP4, ``every`` defaults to 1 and ``fps``
    to real time (clipped to 1..50). For GIF (large and slow to write per
    frame) the defaults keep a movie small and quick: at most
    :data:`GIF_MAX_FRAMES` frames at up to :data:`GIF_FPS` frames per second
    (a long run plays faster than real time), 360 x 360 pixels
    (``dpi=60``); a 60 s, 15-agent GIF takes about 3 s and 1 MB. Give
    ``every``, ``fps`` or ``dpi`` to choose yourself.
    """
    from .movie import check_movie_path
    path = check_movie_path(path)
    if path.suffix.lower() == ".gif":
        T = len(results.t)
        dt = float(np.median(np.diff(results.t))) if T > 1 else 0.1
        if every is None:
            every = max(1, math.ceil(1.0 / (GIF_FPS * dt)) if dt > 0 else 1,
                        math.ceil(T / GIF_MAX_FRAMES))
        if fps is None:
            frames = math.ceil(T / every)
            span = max(float(results.t[-1] - results.t[0]), 1e-9) if T > 1 else 1.0
            fps = float(np.clip(frames / span, 1.0, GIF_FPS))
            if frames / fps > 20.0:     # play long runs in at most ~20 s
                fps = float(min(GIF_FPS, frames / 20.0))
        options.setdefault("dpi", GIF_DPI)
    anim = Animation(results, pose, every=1 if every is None else every, **options)
    try:
        return anim.save(path, fps, progress=progress)
    finally:
        anim.close()
