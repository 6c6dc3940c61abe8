"""The ``world`` section of a scenario file: obstacles, bounds and walls as data."""

from __future__ import annotations

import numpy as np

from ..core.errors import AvError, ScenarioError

_WORLD_KEYS = {"obstacles", "bounds", "walls", "image", "geojson", "wkt"}


def _obstacle(ob, where, source=None):
    from ..environment.world import Circle
    if isinstance(ob, dict):
        if set(ob) == {"circle"} and isinstance(ob["circle"], dict):
            ob = ob["circle"]
        if set(ob) == {"center", "radius"}:
            c = np.asarray(ob["center"], dtype=float)
            return Circle(tuple(c.tolist()) if c.ndim == 1 else c, float(ob["radius"]))
        if set(ob) == {"polygon"}:
            return ob["polygon"]
        raise ScenarioError("an obstacle is a list of [x, y] vertices, {polygon: "
                            "[[x, y], ...]} or {circle: {center: [x, y], radius: r}}",
                            file=source, entry=where,
                            hint=f"found keys {sorted(map(str, ob))}")
    return ob


def _parse_world(spec, where, folder, source=None):
    """A :class:`~avblocks.environment.World` from a scenario mapping::

        world:
          bounds: [0, 0, 50, 50]          # xmin, ymin, xmax, ymax
          walls: true
          obstacles: [[[10, 10], [20, 10], [15, 20]], {circle: {center: [30, 30], radius: 4}}]
        # or instead of obstacles: image: {path: map.png, resolution: 0.05},
        #   geojson: obstacles.geojson (files under the scenario's folder), wkt: "POLYGON(...)"
    """
    import json

    from .paths import inside
    try:
        from ..environment import World
    except ImportError as e:
        raise ScenarioError("a 'world' needs avblocks.environment.World",
                            file=source, entry=where) from e
    if not isinstance(spec, dict):
        raise ScenarioError("a world is a mapping like {obstacles: [...], bounds: [...]}",
                            file=source, entry=where)
    unknown = set(map(str, spec)) - _WORLD_KEYS
    if unknown:
        raise ScenarioError(f"unknown world key(s) {sorted(unknown)}", file=source,
                            entry=where, hint=f"known: {sorted(_WORLD_KEYS)}")
    sources = [k for k in ("obstacles", "image", "geojson", "wkt") if k in spec]
    if len(sources) > 1:
        raise ScenarioError(f"give the obstacles one way, not {sources}", file=source,
                            entry=where)
    kw = {}
    if spec.get("bounds") is not None:
        kw["bounds"] = spec["bounds"]
    if "walls" in spec:
        if not isinstance(spec["walls"], bool):
            raise ScenarioError("walls must be true or false", file=source,
                                entry=f"{where}.walls")
        kw["walls"] = spec["walls"]
    try:
        if "image" in spec:
            im = spec["image"]
            if not isinstance(im, dict) or "path" not in im:
                raise ScenarioError("image is {path: file, resolution: metres per pixel,"
                                    " origin: [x, y]}", file=source, entry=f"{where}.image")
            opts = {k: v for k, v in im.items() if k != "path"}
            bad = set(opts) - {"resolution", "origin", "occupied_thresh", "negate"}
            if bad:
                raise ScenarioError(f"unknown image option(s) {sorted(map(str, bad))}",
                                    file=source, entry=f"{where}.image")
            path = inside(im["path"], folder, what=f"{where}.image.path", source=source,
                          must_exist=True)
            return World.from_image(str(path), **opts, **kw)
        if "geojson" in spec:
            g = spec["geojson"]
            if isinstance(g, str):
                path = inside(g, folder, what=f"{where}.geojson", source=source,
                              must_exist=True)
                g = json.loads(path.read_text(encoding="utf-8"))
            return World.from_geojson(g, **kw)
        if "wkt" in spec:
            return World.from_wkt(spec["wkt"], **kw)
        obs = spec.get("obstacles") or []
        if not isinstance(obs, list):
            raise ScenarioError("obstacles must be a list", file=source,
                                entry=f"{where}.obstacles")
        return World([_obstacle(o, f"{where}.obstacles[{j}]", source) for j, o in enumerate(obs)],
                     **kw)
    except ScenarioError:
        raise
    except AvError as e:
        raise ScenarioError(str(e), file=source, entry=where) from None
    except (TypeError, ValueError, KeyError, OverflowError, MemoryError, OSError,
            RecursionError) as e:
        raise ScenarioError(f"bad world: {type(e).__name__}: {e}", file=source,
                            entry=where) from None
