"""Choosing a headless OpenGL backend for MuJoCo before it is imported.

MuJoCo reads ``MUJOCO_GL`` once, when ``import mujoco`` runs, and without a
display the default (GLFW) cannot render. :func:`import_mujoco` therefore

1. keeps ``MUJOCO_GL`` if the user set it (``egl``, ``osmesa`` or ``glfw``);
2. else probes, in a child process (a failed GL start can't be undone in
   this one), ``egl`` then ``osmesa``: the first that creates an offscreen
   context and renders one frame wins, and is written to ``MUJOCO_GL``
   (and ``PYOPENGL_PLATFORM``) of this process;
3. raises :class:`MuJoCoUnavailable` naming what to install when neither
   works (only when something renders: physics alone needs no OpenGL), or
   when mujoco itself is missing.

The probe costs one short child process (~1 s) per Python process, once.
"""

from __future__ import annotations

import os
import subprocess
import sys

from ...core.errors import AvError

BACKENDS = ("egl", "osmesa")

_PROBE = """
import mujoco
m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=".1"/></worldbody></mujoco>')
d = mujoco.MjData(m)
mujoco.mj_forward(m, d)
r = mujoco.Renderer(m, 8, 8)
r.update_scene(d)
assert r.render().shape == (8, 8, 3)
print("ok")
"""

INSTALL_HINT = (
    "install an offscreen OpenGL: on Debian/Ubuntu `sudo apt install libegl1 "
    "libgl1` (EGL, with a GPU driver or Mesa's libegl-mesa0) or `sudo apt install "
    "libosmesa6` (software OSMesa); then MuJoCo renders without a display. To "
    "force one, set MUJOCO_GL=egl or MUJOCO_GL=osmesa before starting Python")


class MuJoCoUnavailable(AvError, ImportError):
    """MuJoCo is not installed, or no headless OpenGL backend works."""


_chosen = None
_failed = None          # the MuJoCoUnavailable of a failed choice, if any


def _env_for(backend):
    env = dict(os.environ)
    env["MUJOCO_GL"] = backend
    if backend in ("egl", "osmesa"):
        env["PYOPENGL_PLATFORM"] = backend
    return env


def probe(backend, timeout=60.0):
    """True when ``backend`` renders a frame in a child process."""
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE], env=_env_for(backend),
                           capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0 and "ok" in r.stdout


def choose_backend():
    """The headless backend to use (sets ``MUJOCO_GL`` if unset); see module doc."""
    global _chosen
    if _chosen is not None:
        return _chosen
    user = os.environ.get("MUJOCO_GL")
    if user:
        _chosen = user.lower()
        if _chosen in BACKENDS:
            os.environ.setdefault("PYOPENGL_PLATFORM", _chosen)
        return _chosen
    if "mujoco" in sys.modules:
        # imported already (by the user) with MuJoCo's default backend
        _chosen = "default"
        return _chosen
    for b in BACKENDS:
        if probe(b):
            os.environ["MUJOCO_GL"] = b
            os.environ["PYOPENGL_PLATFORM"] = b
            _chosen = b
            return b
    raise MuJoCoUnavailable("no headless OpenGL backend works for MuJoCo "
                            f"(tried {', '.join(BACKENDS)})", hint=INSTALL_HINT)


def import_mujoco(render=False):
    """``import mujoco`` after choosing a headless backend; clear errors.

    Physics alone needs no OpenGL: with ``render=False`` a missing backend
    is remembered, not raised (MuJoCo still imports); ``render=True`` (the
    camera block) raises :class:`MuJoCoUnavailable` then.
    """
    global _failed
    try:
        import importlib.util
        if importlib.util.find_spec("mujoco") is None:
            raise ImportError
    except ImportError:
        raise MuJoCoUnavailable("the mujoco package is not installed",
                                hint="pip install 'avblocks[mujoco]'") from None
    if _failed is not None and render:
        raise _failed
    if _failed is None:
        try:
            choose_backend()
        except MuJoCoUnavailable as e:
            _failed = e
            if render:
                raise
    import mujoco
    return mujoco
