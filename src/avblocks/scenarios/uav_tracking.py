"""A quadrotor visually tracks a red ground vehicle (AVLib paper, case study
IV.C), in MuJoCo with a downward camera and OpenCV colour tracking.

Set-up
------
- The ground vehicle is a plain :class:`~avblocks.vehicles.Unicycle`
  driven by :class:`~avblocks.controllers.PointToPoint` through
  :data:`WAYPOINTS`, a loop that weaves between the obstacles of
  :data:`WORLD` (boxes, a concave wall, cylinders, all 1 m high). MuJoCo
  shows it as a red kinematic body (co-simulation: 2D model + 3D scene).
- The quadrotor is simulated by MuJoCo (:class:`PhysicsWorld`, the ports of
  :class:`~avblocks.vehicles.Quadrotor`; ``physics="model"`` puts
  ``vehicles.Quadrotor`` in its place, nothing else changes) and flown by
  :class:`~avblocks.vehicles.QuadrotorVelocityControl`.
- The chain, at the camera rate (``camera_rate`` Hz)::

    SceneCamera (downward, width x height) -> ColorBlobTracker (red)
    -> GroundPointEstimator (pixel -> ground point at the vehicle's centre
       height, from the quadrotor's pose) -> TrackingController
    -> velocity set-point -> QuadrotorVelocityControl -> quadrotor

:class:`~avblocks.controllers.TrackingController` filters the ground point with an alpha-beta
filter (position and velocity of the target) and commands::

    v_xy = v_hat + k_p (p_hat - p_xy),  |v_xy| <= v_max
    v_z  = k_z (altitude - p_z)

The velocity feed-forward ``v_hat`` removes the steady lag ``V / k_p`` that
a pure P law leaves behind a vehicle moving at speed V.

The scenario file ``uav_tracking.yaml`` is this module's twin (the same
blocks, the drone as ``interfaces.mujoco.PhysicsWorld`` plus
``vehicles.QuadrotorVelocityControl``, the scene of :func:`build_scene`
given by numbers in a ``{mujoco_scene: ...}`` value): it is what ``avblocks
run uav_tracking`` runs and what the editor opens, to the same numbers.
``physics="model"`` is this module's; in the file, give the block ``uav``
the type ``vehicles.Quadrotor``.

Outputs of ``avblocks run uav_tracking``: ``results.nc``, ``tracking.mp4``
(the scene camera and the drone's camera side by side, the tracked blob
boxed), ``tracking_error.png`` and an outcome line (largest and RMS
horizontal error, frames with the vehicle found / in view).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from avblocks.controllers import PointToPoint, TrackingController
from avblocks.core.diagram import Diagram
from avblocks.environment import Circle, World, rectangle
from avblocks.scenarios.report import save_figure
from avblocks.vehicles import Quadrotor, Unicycle, velocity_controlled_quadrotor

#: Obstacles: boxes, a concave L-wall, cylinders (all extruded to 1 m).
WORLD = World([rectangle(1.0, 1.0, 2.5, 2.0), rectangle(-4.5, -1.0, -3.5, 1.5),
               [(3.0, -3.5), (6.0, -3.5), (6.0, -2.5), (4.0, -2.5), (4.0, -1.5),
                (3.0, -1.5)],
               Circle((-1.0, 4.5), 0.6), Circle((5.5, 3.0), 0.5), Circle((-2.5, -4.0), 0.7)],
              bounds=(-8.0, -7.0, 9.0, 8.0))
#: The vehicle's loop (x, y), clear of the obstacles by >= 0.8 m.
WAYPOINTS = np.array([[3.0, 0.0], [4.5, 1.5], [3.5, 3.5], [0.0, 3.5], [-2.5, 2.5],
                      [-2.0, -0.5], [-0.5, -2.5], [2.0, -0.3], [0.0, 0.0], [-1.5, 1.0]])
TARGET_RADIUS = 0.25
TARGET_HEIGHT = 0.12


def build_scene(altitude, width, height, fovy, uav0, target0, scene_view=True,
                view_size=(320, 240)):
    from avblocks.interfaces.mujoco import CameraMount, Scene
    # the offscreen buffer as small as the largest camera: software GL pays
    # for every pixel of it on each render
    big = (max(width, view_size[0]), max(height, view_size[1])) if scene_view else (
        width, height)
    scene = Scene(WORLD, obstacle_height=1.0, max_image=big)
    scene.add_ground_robots("target", [target0], radius=TARGET_RADIUS, height=TARGET_HEIGHT,
                            color=(0.85, 0.05, 0.05), marker=False, kinematic=True)
    mount = CameraMount(pos=(0.0, 0.0, -0.06), fovy=float(fovy))
    scene.add_quadrotors("uav", [uav0], camera=mount, color=(0.15, 0.15, 0.18),
                         arm_length=0.25)
    if scene_view:
        scene.add_camera("overview", (0.5, -8.0, 9.0), (0.5, 0.3, 0.0), fovy=55.0)
    return scene, mount


def make_diagram(t_final=40.0, dt=0.01, speed=0.8, altitude=4.0, camera_rate=10.0,
                 width=160, height=120, fovy=60.0, physics="mujoco", scene_view=True,
                 view_size=(320, 240), k_p=1.2, seed=0):
    """The tracking diagram and its simulation settings.

    ``physics``: "mujoco" (PhysicsWorld) or "model" (vehicles.Quadrotor).
    ``scene_view``: also render the overview camera (for the movie).
    """
    from avblocks.interfaces.mujoco import PhysicsWorld, SceneCamera
    from avblocks.interfaces.vision import ColorBlobTracker, GroundPointEstimator

    if physics not in ("mujoco", "model"):
        from avblocks.core.errors import ParameterError
        raise ParameterError("physics must be 'mujoco' or 'model'", param="physics",
                             found=physics)
    period = 1.0 / float(camera_rate)
    target0 = np.array([0.0, 0.0, 0.0])
    uav0 = np.array([-0.6, 0.4, float(altitude)])
    view_size = (int(view_size[0]), int(view_size[1]))
    scene, mount = build_scene(float(altitude), int(width), int(height), fovy, uav0, target0,
                               bool(scene_view), view_size)
    d = Diagram("uav_tracking")
    tgt = d.add(Unicycle([target0]), name="target")
    drive = d.add(PointToPoint(WAYPOINTS, n=1, v_max=float(speed), gain=1.5, radius=0.4),
                  name="drive")
    d.connect(tgt.pose, drive.pose)
    d.connect(drive.cmd, tgt.cmd)
    quad = PhysicsWorld(scene, period=float(dt)) if physics == "mujoco" else \
        Quadrotor([uav0], arm_length=0.25)
    uav = d.add(velocity_controlled_quadrotor(quad), name="uav")
    cam_block = SceneCamera(scene, "uav", width=int(width), height=int(height), period=period)
    cam = d.add(cam_block, name="camera")
    d.connect(tgt.pose, cam.target_pose)
    d.connect(uav.position, cam.uav_position)
    d.connect(uav.attitude, cam.uav_attitude)
    tr = d.add(ColorBlobTracker.red(1, int(height), int(width)), name="tracker")
    d.connect(cam.image, tr.image)
    est = d.add(GroundPointEstimator(1, cam_block.camera_matrix(), mount.pos,
                                     mount.rotation(), z0=TARGET_HEIGHT / 2,
                                     point0=target0), name="estimator")
    d.connect(tr.centroid, est.centroid)
    d.connect(tr.found, est.found)
    d.connect(uav.position, est.position)
    d.connect(uav.attitude, est.attitude)
    ctl = d.add(TrackingController(1, period, k_p=float(k_p), altitude=float(altitude),
                                   start=target0[None]), name="follow")
    d.connect(est.point, ctl.point)
    d.connect(est.valid, ctl.valid)
    d.connect(uav.position, ctl.position)
    d.connect(ctl.velocity, uav.velocity)
    log = ["target.pose", "uav.position", "uav.attitude", "tracker.centroid",
           "tracker.found", "tracker.bbox", "estimator.point", "follow.estimate",
           "camera.image"]
    if scene_view:
        view = d.add(SceneCamera(scene, "overview", width=int(view_size[0]),
                                 height=int(view_size[1]), period=period), name="view")
        d.connect(tgt.pose, view.target_pose)
        d.connect(uav.position, view.uav_position)
        d.connect(uav.attitude, view.uav_attitude)
        log.append("view.image")
    steps = period / float(dt)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4", "log": log,
           "log_every": max(1, int(round(steps))), "seed": int(seed)}
    return d, sim


# ------------------------------------------------------------------ outcome
def tracking_error(res):
    """Horizontal distance (T,) between the quadrotor and the vehicle."""
    return np.linalg.norm(res["uav.position"][:, 0, :2] - res["target.pose"][:, 0, :2], axis=1)


def in_view(res, width, height, fovy=60.0):
    """(T,) True where the vehicle's centre projects inside the drone's image."""
    from avblocks.interfaces.mujoco.scene import CameraMount
    from avblocks.interfaces.vision import PinholeCamera, camera_pose
    mount = CameraMount(pos=(0.0, 0.0, -0.06), fovy=fovy)
    cam = PinholeCamera.from_fov(fovy, width, height)
    c, R = camera_pose(res["uav.position"][:, 0], res["uav.attitude"][:, 0], mount.pos,
                       mount.rotation())
    tp = res["target.pose"][:, 0]
    pts = np.column_stack([tp[:, :2], np.full(len(tp), TARGET_HEIGHT / 2)])
    px, front = cam.project(pts, c, R)
    return front & cam.in_image(px), px


def _mark(img, bbox, found):
    """A copy of ``img`` with a green box around the tracked blob."""
    out = img.copy()
    if not found:
        return out
    h, w = out.shape[:2]
    x0, y0, bw, bh = (int(v) for v in bbox)
    x0, y0 = max(x0 - 2, 0), max(y0 - 2, 0)
    x1, y1 = min(x0 + bw + 3, w - 1), min(y0 + bh + 3, h - 1)
    g = np.array([40, 255, 40], np.uint8)
    out[y0, x0:x1 + 1] = g
    out[y1, x0:x1 + 1] = g
    out[y0:y1 + 1, x0] = g
    out[y0:y1 + 1, x1] = g
    return out


def movie_frames(res):
    """Side-by-side frames: scene view | drone camera (scaled to the same height)."""
    cams = res["camera.image"][:, 0]
    views = res["view.image"][:, 0] if "view.image" in res.keys() else None
    for k in range(len(res.t)):
        c = _mark(cams[k], res["tracker.bbox"][k, 0], res["tracker.found"][k, 0])
        if views is None:
            yield c
            continue
        v = views[k]
        s = max(1, v.shape[0] // c.shape[0])
        c = np.repeat(np.repeat(c, s, axis=0), s, axis=1)
        pad = np.zeros((v.shape[0], c.shape[1], 3), np.uint8)
        pad[:c.shape[0]] = c
        yield np.concatenate([v, np.full((v.shape[0], 4, 3), 255, np.uint8), pad], axis=1)


def outcome(res, params=None):
    """One line and its numbers: horizontal tracking error, frames with the
    blob found, frames with the vehicle in view (``avblocks run`` prints it
    and writes it to summary.json)."""
    err = tracking_error(res)
    seen = res["tracker.found"][:, 0]
    height, width = res["camera.image"].shape[2:4]
    vis, _ = in_view(res, width, height)
    rms = float(np.sqrt(np.mean(err**2)))
    line = (f"tracking: max horizontal error {err.max():.2f} m, RMS {rms:.2f} m, blob "
            f"found in {seen.mean() * 100:.0f} % of frames, vehicle in view in "
            f"{vis.mean() * 100:.0f} %")
    return line, {"max_error_m": float(err.max()), "rms_error_m": rms,
                  "found_fraction": float(seen.mean()), "in_view_fraction": float(vis.mean())}


def figures(res, out, params=None):
    """Write ``tracking_error.png`` and ``tracking.mp4`` (scene view | drone
    camera, tracked blob boxed; needs the movie extra) under ``out``; return
    the paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    out = Path(out)
    err = tracking_error(res)
    seen = res["tracker.found"][:, 0]
    fig, ax = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax[0].plot(res.t, err, label="horizontal error |p_uav - p_vehicle|")
    est_err = np.linalg.norm(res["follow.estimate"][:, 0, :2] - res["target.pose"][:, 0, :2],
                             axis=1)
    ax[0].plot(res.t, est_err, lw=0.8, label="filtered estimate error")
    ax[0].set_ylabel("m")
    ax[0].legend(loc="upper right")
    ax[0].grid(alpha=0.3)
    ax[1].step(res.t, seen.astype(int), where="post", label="blob found")
    ax[1].set_ylim(-0.1, 1.1)
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="lower right")
    fig.suptitle("UAV tracking a ground vehicle by colour (case study IV.C)")
    fig.tight_layout()
    png = out / "tracking_error.png"
    try:
        save_figure(fig, png)                   # folder made, written atomically
    finally:
        plt.close(fig)
    files = [png]
    try:
        from avblocks.viz.movie import write_movie
        mp4 = out / "tracking.mp4"
        dt_log = float(res.t[1] - res.t[0]) if len(res.t) > 1 else 0.1
        write_movie(movie_frames(res), mp4, fps=1.0 / dt_log, total=len(res.t), progress=False)
        files.append(mp4)
    except Exception as e:  # noqa: BLE001 - the movie is optional (ffmpeg extra)
        print(f"(no movie: {e})")
    return files


def report(res, out):
    """``(files, outcome line)``: :func:`figures` and :func:`outcome` together."""
    return figures(res, out), outcome(res)[0]
