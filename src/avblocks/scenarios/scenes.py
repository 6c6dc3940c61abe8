"""The ``mujoco_scene`` value of a scenario file: a MuJoCo scene
(:class:`avblocks.interfaces.mujoco.Scene`) for the blocks that take one
(``interfaces.mujoco.PhysicsWorld``, ``interfaces.mujoco.SceneCamera``).

Two forms. Built from numbers (what ``Scene``'s methods take, in the
order ground robots, quadrotors, fixed cameras)::

    scene:
      mujoco_scene:
        world: {obstacles: [...], bounds: [xmin, ymin, xmax, ymax]}
        obstacle_height: 1.0
        max_image: [320, 240]
        ground_robots:
          target: {pose0: [[0, 0, 0]], radius: 0.25, color: [0.85, 0.05, 0.05],
                   kinematic: true}
        quadrotors:
          uav: {position0: [[0, 0, 4]], camera: {pos: [0, 0, -0.06], fovy: 60}}
        cameras:
          overview: {pos: [0, -8, 9], lookat: [0, 0, 0], fovy: 55}

Or a user's own MJCF file, under the scenario file's folder, with the
bodies that are agents named by group (:meth:`Scene.from_mjcf`)::

    scene:
      mujoco_scene:
        mjcf: my_scene.xml
        ground_robots: {target: [target0]}
        quadrotors: {uav: [uav0]}

(its cameras: a camera ``<body>_cam`` on each body of a quadrotor group is
that group's mount; any other named camera is a fixed one; the offscreen
buffer is the file's ``<visual><global offwidth offheight>``).

Every block that names the scene builds it from the same data (a YAML
anchor, ``scene: &scene {...}`` then ``scene: *scene``, writes it once).
Every failure is a :class:`~avblocks.core.errors.ScenarioError` naming
the file and the entry: an unknown key, a missing or unreadable MJCF file,
XML that MuJoCo refuses, a body that is not in it, or a file the MJCF
includes or loads (``<include>``, meshes, textures, height fields, skins,
sub-models, ``<compiler meshdir texturedir assetdir>``) outside the
scenario file's folder, checked before MuJoCo reads anything
(:meth:`Scene.from_mjcf` with ``folder``).
"""

from __future__ import annotations

from ..core.errors import AvError, ScenarioError
from .paths import inside

_SCENE_KEYS = {"ground", "ground_size", "texture", "obstacle_height", "obstacle_color",
               "timestep", "max_image", "gravity", "shadows"}
_KEYS = _SCENE_KEYS | {"world", "mjcf", "ground_robots", "quadrotors", "cameras"}
_MJCF_KEYS = {"mjcf", "ground_robots", "quadrotors", "shadows"}


def _mapping(v, where, source, what):
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise ScenarioError(f"'{what}' maps group names to their settings", file=source,
                            entry=where)
    return v


def mujoco_scene(spec, where="scene", folder=".", source=None):
    """The :class:`~avblocks.interfaces.mujoco.Scene` a file describes
    (see the module docstring); ``folder`` is the only folder an MJCF file
    or a ground texture may be read from."""
    if not isinstance(spec, dict):
        raise ScenarioError("a mujoco_scene is a mapping (world, ground_robots, "
                            "quadrotors, cameras, ... or mjcf)", file=source, entry=where)
    unknown = set(map(str, spec)) - _KEYS
    if unknown:
        raise ScenarioError(f"unknown mujoco_scene key(s) {sorted(unknown)}", file=source,
                            entry=where, hint=f"known: {sorted(_KEYS)}")
    try:
        from ..interfaces.mujoco import CameraMount, Scene
        if "mjcf" in spec:
            return _from_mjcf(Scene, spec, where, folder, source)
        return _from_numbers(Scene, CameraMount, spec, where, folder, source)
    except ScenarioError:
        raise
    except AvError as e:
        raise ScenarioError(f"mujoco_scene: {e}", file=source, entry=where) from None
    except (TypeError, ValueError) as e:
        raise ScenarioError(f"mujoco_scene: {type(e).__name__}: {e}", file=source,
                            entry=where) from None


def _from_mjcf(Scene, spec, where, folder, source):
    bad = set(map(str, spec)) - _MJCF_KEYS
    if bad:
        raise ScenarioError(f"with 'mjcf' the scene is the file's: {sorted(bad)} cannot "
                            "be given", file=source, entry=where,
                            hint=f"with mjcf: {sorted(_MJCF_KEYS)}")
    path = spec["mjcf"]
    if not isinstance(path, str) or not path.lower().endswith(".xml"):
        raise ScenarioError(f"'mjcf' names an .xml file, found {path!r:.60}", file=source,
                            entry=f"{where}.mjcf")
    full = inside(path, folder, what=f"{where}.mjcf", source=source, must_exist=True)
    try:
        full.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"cannot read the MJCF file '{path}': {e}", file=source,
                            entry=f"{where}.mjcf") from None
    groups = {}
    for kind in ("ground_robots", "quadrotors"):
        g = _mapping(spec.get(kind), f"{where}.{kind}", source, kind)
        for name, bodies in g.items():
            if not (isinstance(bodies, list) and bodies
                    and all(isinstance(b, str) for b in bodies)):
                raise ScenarioError("a group of an MJCF scene is a list of body names",
                                    file=source, entry=f"{where}.{kind}.{name}")
        groups[kind] = g
    kw = {k: spec[k] for k in ("shadows",) if k in spec}
    try:
        return Scene.from_mjcf(str(full), ground_robots=groups["ground_robots"],
                               quadrotors=groups["quadrotors"], folder=folder, **kw)
    except AvError as e:
        raise ScenarioError(f"in the MJCF file '{path}': {e}", file=source,
                            entry=f"{where}.mjcf") from None


def _groups(spec, key, required, what, where, source):
    """``(name, mapping copy, entry)`` of each group under ``spec[key]``,
    each checked to give ``required``."""
    for name, g in _mapping(spec.get(key), f"{where}.{key}", source, key).items():
        at = f"{where}.{key}.{name}"
        g = dict(_mapping(g, at, source, key))
        if required not in g:
            raise ScenarioError(f"{what} needs '{required}'", file=source, entry=at)
        yield name, g, at


def _from_numbers(Scene, CameraMount, spec, where, folder, source):
    from ..environment import World
    from .worlds import _parse_world
    kw = {k: spec[k] for k in _SCENE_KEYS if k in spec}
    world = spec.get("world")
    if isinstance(world, dict):
        world = _parse_world(world, f"{where}.world", folder, source)
    elif world is not None and not isinstance(world, World):
        raise ScenarioError("'world' is a world mapping {obstacles: [...], bounds: [...]}",
                            file=source, entry=f"{where}.world")
    tex = kw.get("texture")
    if isinstance(tex, str) and tex != "checker":
        kw["texture"] = str(inside(tex, folder, what=f"{where}.texture", source=source,
                                   must_exist=True))
    scene = Scene(world, **kw)
    for name, g, at in _groups(spec, "ground_robots", "pose0", "a ground robot group",
                               where, source):
        _add(scene.add_ground_robots, name, g.pop("pose0"), g, at, source)
    for name, g, at in _groups(spec, "quadrotors", "position0", "a quadrotor group",
                               where, source):
        cam = g.get("camera")
        if isinstance(cam, dict):
            bad = set(map(str, cam)) - {"pos", "xyaxes", "fovy"}
            if bad:
                raise ScenarioError(f"unknown camera key(s) {sorted(bad)}", file=source,
                                    entry=f"{at}.camera", hint="known: pos, xyaxes, fovy")
            g["camera"] = CameraMount(**{k: (tuple(float(x) for x in v) if k != "fovy"
                                             else float(v)) for k, v in cam.items()})
        _add(scene.add_quadrotors, name, g.pop("position0"), g, at, source)
    for name, c in _mapping(spec.get("cameras"), f"{where}.cameras", source,
                            "cameras").items():
        at = f"{where}.cameras.{name}"
        c = dict(_mapping(c, at, source, "cameras"))
        if "pos" not in c:
            raise ScenarioError("a fixed camera needs 'pos' (and 'lookat', 'fovy')",
                                file=source, entry=at)
        _add(scene.add_camera, name, c.pop("pos"), c, at, source)
    return scene


def _add(method, name, first, kwargs, where, source):
    try:
        method(name, first, **kwargs)
    except TypeError as e:
        raise ScenarioError(f"{e}", file=source, entry=where) from None
    except AvError as e:
        raise ScenarioError(str(e), file=source, entry=where) from None


def camera_matrix_value(fovy, width, height):
    """Generator ``camera_matrix``: the intrinsic matrix K (3, 3) of a
    MuJoCo camera of vertical field of view ``fovy`` [deg] rendering
    ``width`` x ``height`` pixels (what ``SceneCamera.camera_matrix()``
    returns), e.g. for ``interfaces.vision.GroundPointEstimator``'s ``K``."""
    from ..interfaces.mujoco.camera import camera_matrix
    return camera_matrix(float(fovy), int(width), int(height))


def camera_axes(xyaxes=(0.0, -1.0, 0.0, 1.0, 0.0, 0.0)):
    """Generator ``camera_axes``: the axes (3, 3) in the body frame of a
    camera mounted with MuJoCo ``xyaxes`` (columns x, y, z; what
    ``CameraMount.rotation()`` returns), e.g. for
    ``interfaces.vision.GroundPointEstimator``'s ``mount_rot``. The
    default looks straight down, image top = body forward."""
    from ..interfaces.mujoco.scene import CameraMount
    return CameraMount(xyaxes=tuple(float(v) for v in xyaxes)).rotation()


#: value generators of this module (``{camera_matrix: {fovy: 60, ...}}``)
GENERATORS = {"camera_matrix": camera_matrix_value, "camera_axes": camera_axes}
