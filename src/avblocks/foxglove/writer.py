"""Runs and flights as MCAP files with Foxglove's well-known schemas.

What :func:`write_results` writes (``P`` is the ``prefix``, ``sim`` for a
run and ``flight`` for a flight by default, so both open side by side):

========================  ==========================  =====================================
topic                     schema (encoding)           content
========================  ==========================  =====================================
``/P/tf``                 foxglove.FrameTransforms    every agent's pose, one message per
                          (protobuf)                  logged sample: parent ``world``,
                                                      child ``P/<block>/<agent>``
``/P/bodies``             foxglove.SceneUpdate        one entity per agent, locked to its
                                                      frame: the outline of its body (the
                                                      drawings of :mod:`avblocks.viz.shapes`)
                                                      and its name
``/P/world``              foxglove.SceneUpdate        the obstacles (outlines at z = 0)
``/P/links``              foxglove.SceneUpdate        neighbour lists logged by the run
                                                      (``*.neighbors``) and fixed ``links``,
                                                      as lines between agents, per sample
``/P/signals/<signal>``   ``avblocks.<signal>``       every logged signal, per sample, as
                          (JSON, JSON schema)         ``{"t": .., "agents": [..]}`` (labelled
                                                      components by name): plottable as
                                                      ``/P/signals/fleet.pose.agents[0].x``
``/P/log``                foxglove.Log                the outcome line at the last sample,
                                                      the run's error, the flight's events
``/P/setpoint``           ``avblocks.setpoint`` (JSON)  flights: the velocity set-points sent
``/P/setpoint_arrows``    foxglove.SceneUpdate        ... drawn as arrows at the vehicles
========================  ==========================  =====================================

Message times (the MCAP ``log_time`` and ``publish_time``, and each
message's ``timestamp``) are ``start + t`` in nanoseconds, ``t`` the run's
time: with the default ``start = 0`` a simulated run and a flight of the
same scenario both begin at 0 and play in sync in one Foxglove window.
Flight events logged before the mission (pre-flight, take-off: before the
run's ``t = 0``) are placed at ``t = 0`` and their message says when they
happened.

Which signals are poses: a block's ``position`` (N, 3) or (N, 2) gives
the translation, rotated by its ``attitude`` (N, 4; w, x, y, z) or the
heading of its ``pose`` when logged; a block's ``pose`` (N, 3) alone is
planar (x, y, heading). Signals are named as the run logged them (a
subsystem's ``fleet.position``, not ``fleet.quad.position``).

References
----------
MCAP file format specification (mcap.dev/spec); Foxglove message schemas
(docs.foxglove.dev/docs/visualization/message-schemas): FrameTransforms,
SceneUpdate, SceneEntity, LinePrimitive, ArrowPrimitive, Log.
"""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
from pathlib import Path

import numpy as np

from ..core.errors import AvError, ParameterError

#: the agents' colours (RGB in [0, 1]), one per pose source
PALETTE = [(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16),
           (0.58, 0.4, 0.74), (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.5, 0.5, 0.5)]

_PREFIX = re.compile(r"^[A-Za-z0-9_-]{1,40}$")


def _fg():
    try:
        import foxglove
        import foxglove.channels as channels
        import foxglove.messages as messages
    except ImportError as e:
        raise AvError(f"writing MCAP files needs foxglove-sdk: {e}",
                      hint="pip install 'avblocks[foxglove]'") from None
    return foxglove, channels, messages


# ---------------------------------------------------------------- what the run holds
def display_names(results) -> dict:
    """``{data key: the name the run logged it by}`` (the shortest alias)."""
    out = {k: k for k in results.data}
    for alias, key in sorted(results.aliases.items(), key=lambda kv: len(kv[0])):
        if key in out and out[key] == key:
            out[key] = alias
    return out


def pose_sources(results) -> list[dict]:
    """The blocks whose logged signals give poses (module docstring):
    ``[{"block", "n", "xyz" (T, N, 3), "quat" (T, N, 4) (x, y, z, w),
    "planar"}]`` in the order of the results' signals."""
    names = display_names(results)
    by_block = {}
    for key, name in names.items():
        block, _, port = name.rpartition(".")
        by_block.setdefault(block, {})[port] = key
    out = []
    for block, ports in by_block.items():
        get = {p: np.asarray(results.data[k]) for p, k in ports.items()}
        pos, pose, att = get.get("position"), get.get("pose"), get.get("attitude")
        T = len(results.t)

        def fits(a, k):
            return a is not None and a.ndim == 3 and a.shape[2] == k and \
                np.dtype(a.dtype).kind == "f"

        if fits(pos, 3) or fits(pos, 2):
            n = pos.shape[1]
            xyz = np.zeros((T, n, 3))
            xyz[..., :pos.shape[2]] = pos
            if fits(att, 4) and att.shape[1] == n:
                q = att / np.maximum(np.linalg.norm(att, axis=-1, keepdims=True), 1e-300)
                quat = np.concatenate([q[..., 1:], q[..., :1]], axis=-1)
            elif fits(pose, 3) and pose.shape[1] == n:
                quat = _yaw_quat(pose[..., 2])
            else:
                quat = np.zeros((T, n, 4))
                quat[..., 3] = 1.0
            out.append({"block": block, "n": n, "xyz": xyz, "quat": quat,
                        "planar": pos.shape[2] == 2 or not fits(att, 4)})
        elif fits(pose, 3):
            n = pose.shape[1]
            xyz = np.zeros((T, n, 3))
            xyz[..., :2] = pose[..., :2]
            out.append({"block": block, "n": n, "xyz": xyz, "quat": _yaw_quat(pose[..., 2]),
                        "planar": True})
    return out


def _yaw_quat(yaw):
    """Quaternions (x, y, z, w) of rotations by ``yaw`` about z."""
    yaw = np.nan_to_num(np.asarray(yaw, float))
    z = np.zeros_like(yaw)
    return np.stack([z, z, np.sin(yaw / 2), np.cos(yaw / 2)], axis=-1)


def _signal_schema(name, spec, shape, dtype):
    """JSON schema of one sample of a signal (see :func:`_signal_message`)."""
    kind = np.dtype(dtype).kind
    scalar = {"b": {"type": ["boolean", "null"]},
              "i": {"type": ["integer", "null"]},
              "u": {"type": ["integer", "null"]}}.get(kind, {"type": ["number", "null"]})
    labels = tuple(getattr(spec, "labels", ()) or ())
    agents = bool(getattr(spec, "agents", True)) and len(shape) >= 1

    def nested(dims):
        if not dims:
            return scalar
        if len(dims) == 1 and labels and len(labels) == dims[0]:
            return {"type": "object", "properties": {lb: scalar for lb in labels},
                    "required": list(labels)}
        return {"type": "array", "items": nested(dims[1:]), "minItems": dims[0],
                "maxItems": dims[0]}

    props = {"t": {"type": "number", "description": "the run's time [s]"}}
    if agents:
        props["agents"] = nested(tuple(shape))
    else:
        props["value"] = nested(tuple(shape))
    unit = getattr(spec, "unit", "") or ""
    return {"title": f"avblocks.{name}", "type": "object", "properties": props,
            "required": list(props), "description": f"{name} [{unit}]" if unit else name}


def _jsonable(a, labels):
    """Nested lists of ``a`` with NaN/inf as None, the last axis as a dict of
    ``labels`` when they fit."""
    if a.ndim == 0:
        v = a.item()
        return v if not isinstance(v, float) or math.isfinite(v) else None
    if a.ndim == 1 and labels and len(labels) == a.shape[0]:
        return {lb: _jsonable(a[j], ()) for j, lb in enumerate(labels)}
    return [_jsonable(x, labels) for x in a]


def _ns(start_ns, t):
    return start_ns + int(round(float(t) * 1e9))


# ---------------------------------------------------------------- the writer
class _Writer:
    """One MCAP file being written through its own foxglove Context."""

    def __init__(self, path, start):
        self.fox, self.ch, self.msg = _fg()
        self.ctx = self.fox.Context()
        self.path = path
        self.writer = self.fox.open_mcap(str(path), allow_overwrite=True, context=self.ctx)
        self.start_ns = int(round(float(start) * 1e9))
        self.channels = {}

    def stamp(self, t):
        ns = _ns(self.start_ns, t)
        return self.msg.Timestamp(sec=ns // 10**9, nsec=ns % 10**9), ns

    def typed(self, topic, kind):
        c = self.channels.get(topic)
        if c is None:
            c = self.channels[topic] = getattr(self.ch, f"{kind}Channel")(topic,
                                                                        context=self.ctx)
        return c

    def json_channel(self, topic, schema):
        c = self.channels.get(topic)
        if c is None:
            sch = self.fox.Schema(name=schema["title"], encoding="jsonschema",
                                  data=json.dumps(schema).encode())
            c = self.channels[topic] = self.fox.Channel(topic, schema=sch,
                                                        message_encoding="json",
                                                        context=self.ctx)
        return c

    def log_json(self, topic, schema, obj, ns):
        self.json_channel(topic, schema).log(json.dumps(obj, allow_nan=False).encode(),
                                             log_time=ns)

    def close(self, metadata):
        self.writer.write_metadata("avblocks", metadata)
        self.writer.close()


def _color(msg, rgb, a=1.0):
    return msg.Color(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(a))


def _point(msg, p):
    return msg.Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]) if len(p) > 2 else 0.0)


def _body_lines(msg, drawing, size, rgb, lift):
    from ..viz.shapes import drawing as make_drawing
    dr = make_drawing(drawing)
    if not hasattr(dr, "parts"):
        raise ParameterError("the body drawing must be a built-in name or vertices",
                             param="drawing", found=type(drawing).__name__)
    lines = []
    for part, fixed in zip(dr.parts, dr.fixed):
        pts = [part[0]]
        for p in part[1:]:
            if not np.allclose(p, pts[-1]):
                pts.append(p)
        colour = (0.2, 0.2, 0.2) if fixed else rgb
        lines.append(msg.LinePrimitive(
            type=msg.LinePrimitiveLineType.LineLoop, thickness=0.02 * max(size, 0.1),
            points=[_point(msg, (size * x, size * y, lift)) for x, y in pts],
            color=_color(msg, colour)))
    return lines


def _obstacle_rings(obstacles):
    if obstacles is None:
        return []
    from ..viz.scene import obstacle_paths
    rings = []
    for p in obstacle_paths(obstacles):
        rings += [np.asarray(r, float) for r in p.to_polygons(closed_only=False) if len(r)]
    return rings


def _check_options(results, path, prefix, every, start, size, links):
    from ..core.results import Results
    if not isinstance(results, Results):
        raise ParameterError("write_results needs Results", param="results",
                             found=type(results).__name__)
    if results.runs is not None:
        raise ParameterError("an MCAP file holds one run", param="results",
                             found=f"an ensemble of {results.runs} runs",
                             hint="write res.run(r) for run r")
    if not _PREFIX.match(str(prefix)):
        raise ParameterError("prefix is a short name of letters, digits, '_' or '-'",
                             param="prefix", found=prefix)
    path = Path(path)
    if path.suffix != ".mcap":
        raise ParameterError("an MCAP file name ends in .mcap", param="path", found=str(path))
    if not path.parent.is_dir():
        raise AvError(f"cannot write '{path}': no folder '{path.parent}'")
    try:
        every = int(every)
        start = float(start)
    except (TypeError, ValueError):
        raise ParameterError("every is a whole number >= 1, start a number of seconds",
                             param="every", found=(every, start)) from None
    if every < 1 or not math.isfinite(start) or start < 0:
        raise ParameterError("every must be >= 1 and start a time >= 0 [s]", param="every",
                             found=(every, start))
    if size is not None and not (isinstance(size, (int, float)) and size > 0):
        raise ParameterError("size is a body size > 0 [m]", param="size", found=size)
    if links is not None:
        links = np.asarray(links)
        if links.ndim != 2 or links.shape[1] != 2 or links.dtype.kind not in "iu":
            raise ParameterError("links are pairs of agent indices", param="links",
                                 expected="an (E, 2) integer array", found=links.shape)
    return path, every, start, links


def write_results(results, path, *, prefix="sim", start=0.0, outcome=None, obstacles=None,
                  links=None, drawing=None, size=None, every=1, flight_log=None,
                  names=None) -> Path:
    """Write ``results`` (one run) to the MCAP file ``path`` (module docstring).

    Parameters
    ----------
    results : Results
    path : str or Path
        Ends in ``.mcap``; written under a temporary name and renamed into
        place when complete (an existing file is replaced).
    prefix : str
        Topic and frame prefix (``"sim"``; ``"flight"`` for a flight).
    start : float
        Unix time [s] of the run's ``t = 0`` (default 0: runs and flights
        line up).
    outcome : str, optional
        The outcome line (default ``results.meta["outcome"]`` if any).
    obstacles : World, shapely geometries or (M, 2) vertices, optional
        Drawn on ``/P/world`` (as :func:`avblocks.viz.animate` takes them).
    links : (E, 2) int array, optional
        Fixed links between agents of the first pose source (a leader tree,
        a communication graph), drawn with the logged neighbour lists.
    drawing : str, optional
        Body outline (a name of :data:`avblocks.viz.shapes.DRAWINGS`);
        default ``"unicycle"`` for planar agents, ``"quadrotor"`` for 3-D.
    size : float, optional
        Body size [m] (default 0.4 planar, 0.3 in 3-D).
    every : int
        Write every ``every``-th sample.
    flight_log : path or FlightLog, optional
        A drone flight's JSON-lines log: its set-points and events are
        written too (``/P/setpoint``, ``/P/setpoint_arrows``, ``/P/log``).
    names : list of str, optional
        Agent names for the labels (default: the flight log's vehicles, else
        the agent indices).

    Returns
    -------
    Path

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> r = av.Results(np.array([0.0, 1.0]), {"fleet.pose": np.zeros((2, 3, 3))})
    >>> import tempfile, pathlib
    >>> p = r.to_mcap(pathlib.Path(tempfile.mkdtemp()) / "run.mcap")
    >>> p.suffix, p.stat().st_size > 0
    ('.mcap', True)
    """
    from .flightlog import FlightLog, read_flight_log
    path, every, start, links = _check_options(results, path, prefix, every, start, size,
                                               links)
    flight = None
    if flight_log is not None:
        flight = flight_log if isinstance(flight_log, FlightLog) else \
            read_flight_log(flight_log)
    if names is None and flight is not None and flight.vehicles:
        names = flight.vehicles
    if outcome is None:
        outcome = results.meta.get("outcome")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        w = _Writer(tmp, start)
        meta = _write(w, results, prefix, every, outcome, obstacles, links, drawing, size,
                      flight, names)
        w.close(meta)
        os.replace(tmp, path)
    except OSError as e:
        raise AvError(f"could not write '{path}': {e.strerror or e}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _write(w, results, prefix, every, outcome, obstacles, links, drawing, size, flight,
           names):
    msg = w.msg
    t = np.asarray(results.t, float)
    idx = np.arange(0, len(t), every)
    if len(t) and idx[-1] != len(t) - 1:
        idx = np.append(idx, len(t) - 1)          # the last sample always
    t0 = float(t[0]) if len(t) else 0.0
    sources = pose_sources(results)
    # ---- bodies (once, locked to their frames) and the world
    stamp0, ns0 = w.stamp(max(t0, 0.0))
    ents = []
    for k, src in enumerate(sources):
        planar = src["planar"]
        dr = drawing or ("unicycle" if planar else "quadrotor")
        sz = size or (0.4 if planar else 0.3)
        rgb = PALETTE[k % len(PALETTE)]
        lines = _body_lines(msg, dr, sz, rgb, 0.0)
        for i in range(src["n"]):
            label = str(names[i]) if names is not None and i < len(names) and k == 0 \
                else str(i)
            ents.append(msg.SceneEntity(
                timestamp=stamp0, frame_id=_frame(prefix, src["block"], i),
                id=f"{src['block']}/{i}", frame_locked=True, lines=lines,
                metadata=[msg.KeyValuePair(key="agent", value=str(i)),
                          msg.KeyValuePair(key="block", value=src["block"])],
                texts=[msg.TextPrimitive(
                    pose=msg.Pose(position=msg.Vector3(x=0.0, y=0.0, z=0.6 * sz),
                                  orientation=msg.Quaternion(x=0, y=0, z=0, w=1)),
                    billboard=True, font_size=14.0, scale_invariant=True, text=label,
                    color=_color(msg, rgb))]))
    if ents:
        w.typed(f"/{prefix}/bodies", "SceneUpdate").log(msg.SceneUpdate(entities=ents),
                                                         log_time=ns0)
    rings = _obstacle_rings(obstacles)
    if rings:
        obs = [msg.SceneEntity(
            timestamp=stamp0, frame_id="world", id=f"obstacle/{j}",
            lines=[msg.LinePrimitive(type=msg.LinePrimitiveLineType.LineLoop, thickness=0.04,
                                     points=[_point(msg, (x, y, 0.0)) for x, y in r[:, :2]],
                                     color=_color(msg, (0.35, 0.35, 0.35)))])
               for j, r in enumerate(rings)]
        w.typed(f"/{prefix}/world", "SceneUpdate").log(msg.SceneUpdate(entities=obs),
                                                        log_time=ns0)
    # ---- per sample: transforms, links, signals
    tf = w.typed(f"/{prefix}/tf", "FrameTransforms") if sources else None
    shown = display_names(results)
    neighbor_keys = [k for k in results.data
                     if shown[k].rpartition(".")[2].endswith("neighbors")
                     and np.asarray(results.data[k]).dtype.kind in "iu"
                     and np.asarray(results.data[k]).ndim == 3]
    first = sources[0] if sources else None
    link_ch = None
    if first is not None and (neighbor_keys or links is not None):
        link_ch = w.typed(f"/{prefix}/links", "SceneUpdate")
    schemas = {k: _signal_schema(shown[k], results.ports.get(k),
                                 np.asarray(results.data[k]).shape[1:],
                                 np.asarray(results.data[k]).dtype)
               for k in results.data}
    for j in idx:
        stamp, ns = w.stamp(t[j])
        if tf is not None:
            trs = []
            for src in sources:
                xyz, q = src["xyz"][j], src["quat"][j]
                for i in range(src["n"]):
                    trs.append(msg.FrameTransform(
                        timestamp=stamp, parent_frame_id="world",
                        child_frame_id=_frame(prefix, src["block"], i),
                        translation=msg.Vector3(x=_f(xyz[i, 0]), y=_f(xyz[i, 1]),
                                                z=_f(xyz[i, 2])),
                        rotation=msg.Quaternion(x=_f(q[i, 0]), y=_f(q[i, 1]),
                                                z=_f(q[i, 2]), w=_f(q[i, 3], 1.0))))
            tf.log(msg.FrameTransforms(transforms=trs), log_time=ns)
        if link_ch is not None:
            pts = []
            p = first["xyz"][j]
            pairs = [] if links is None else [tuple(e) for e in links]
            for k in neighbor_keys:
                nb = np.asarray(results.data[k][j])
                if nb.shape[0] != first["n"]:
                    continue
                pairs += [(a, int(b)) for a in range(nb.shape[0]) for b in nb[a] if b >= 0]
            for a, b in pairs:
                if 0 <= a < first["n"] and 0 <= b < first["n"]:
                    pts += [_point(msg, p[a]), _point(msg, p[b])]
            link_ch.log(msg.SceneUpdate(entities=[msg.SceneEntity(
                timestamp=stamp, frame_id="world", id="links",
                lines=[msg.LinePrimitive(type=msg.LinePrimitiveLineType.LineList,
                                         thickness=0.02, points=pts,
                                         color=_color(msg, (0.3, 0.3, 0.8), 0.6))])]),
                log_time=ns)
        for k, v in results.data.items():
            a = np.asarray(v[j])
            spec = results.ports.get(k)
            labels = tuple(getattr(spec, "labels", ()) or ())
            agents = bool(getattr(spec, "agents", True)) and a.ndim >= 1
            body = {"t": float(t[j]), ("agents" if agents else "value"): _jsonable(a, labels)}
            w.log_json(f"/{prefix}/signals/{shown[k]}", schemas[k], body, ns)
    # ---- a flight's set-points and events
    logs = []
    if flight is not None:
        _write_flight(w, prefix, flight, sources, t, logs)
    t_end = float(t[-1]) if len(t) else 0.0
    if results.meta.get("error"):
        logs.append((t_end, "Error", f"the run failed: {results.meta['error']}"))
    if outcome:
        logs.append((t_end, "Info", f"outcome: {outcome}"))
    if logs:
        ch = w.typed(f"/{prefix}/log", "Log")
        for tt, level, text in sorted(logs, key=lambda x: x[0]):
            stamp, ns = w.stamp(max(tt, 0.0))
            ch.log(msg.Log(timestamp=stamp, level=getattr(msg.LogLevel, level),
                           message=text, name=f"avblocks/{prefix}"), log_time=ns)
    return {"prefix": prefix, "start": repr(w.start_ns / 1e9),
            "outcome": str(outcome or ""),
            "meta": json.dumps(results.meta, default=str)[:100_000],
            "samples": str(len(idx)), "agents": str(sum(s["n"] for s in sources))}


def _frame(prefix, block, i):
    return f"{prefix}/{block.replace('.', '/')}/{i}"


def _f(v, default=0.0):
    v = float(v)
    return v if math.isfinite(v) else default


_LEVELS = {"failsafe": "Error", "abort": "Error", "preflight_refused": "Error",
           "land_timeout": "Warning"}


def _write_flight(w, prefix, flight, sources, t, logs):
    """Set-points as JSON and arrows; events as log lines (see the module)."""
    msg = w.msg
    n = flight.setpoints.shape[1] if flight.setpoints.ndim == 3 else 0
    labels = ("x", "y", "z")
    schema = {"title": "avblocks.setpoint", "type": "object",
              "description": "velocity set-points sent to the vehicles [m/s], world ENU",
              "properties": {"t": {"type": "number"},
                             "agents": {"type": "array", "minItems": n, "maxItems": n,
                                        "items": {"type": "object", "required": list(labels),
                                                  "properties": {c: {"type": "number"}
                                                                 for c in labels}}}},
              "required": ["t", "agents"]}
    src = next((s for s in sources if s["n"] == n), None)
    arrows = w.typed(f"/{prefix}/setpoint_arrows", "SceneUpdate") if src is not None \
        and n else None
    for tk, v in zip(flight.t, flight.setpoints):
        stamp, ns = w.stamp(max(float(tk), 0.0))
        w.log_json(f"/{prefix}/setpoint", schema,
                   {"t": float(tk), "agents": _jsonable(np.asarray(v), labels)}, ns)
        if arrows is None or not len(t):
            continue
        j = int(np.clip(np.searchsorted(t, tk), 0, len(t) - 1))
        ents = []
        for i in range(n):
            speed = float(np.linalg.norm(v[i]))
            if speed < 1e-9:
                continue
            u = v[i] / speed
            q = np.array([0.0, -u[2], u[1], 1.0 + u[0]])       # x axis -> u
            q = q / np.linalg.norm(q) if np.linalg.norm(q) > 1e-9 else \
                np.array([0.0, 0.0, 1.0, 0.0])
            ents.append(msg.ArrowPrimitive(
                pose=msg.Pose(position=msg.Vector3(x=_f(src["xyz"][j, i, 0]),
                                                   y=_f(src["xyz"][j, i, 1]),
                                                   z=_f(src["xyz"][j, i, 2])),
                              orientation=msg.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])),
                shaft_length=0.8 * speed, shaft_diameter=0.03, head_length=0.2 * speed,
                head_diameter=0.08, color=_color(msg, (0.85, 0.1, 0.1))))
        arrows.log(msg.SceneUpdate(entities=[msg.SceneEntity(
            timestamp=stamp, frame_id="world", id="setpoints", arrows=ents)]), log_time=ns)
    for rec in flight.events:
        if rec["ev"] == "cmd":
            continue
        tt = flight.run_time(rec)
        text = rec["ev"] + ": " + ", ".join(
            f"{k}={json.dumps(v)[:200]}" for k, v in rec.items() if k not in ("ev", "wall"))
        if tt is None or tt < 0:
            when = "before the set-points" if tt is None else f"t = {tt:.2f} s"
            text = f"[{when}] {text}"
            tt = 0.0
        logs.append((tt, _LEVELS.get(rec["ev"], "Info"), text))


def write_flight(results, flight_log, path, *, prefix="flight", **options) -> Path:
    """:func:`write_results` of a drone flight: its results (the telemetry
    the fleet block logged) and its JSON-lines flight log (set-points and
    events), under the prefix ``flight``."""
    return write_results(results, path, prefix=prefix, flight_log=flight_log, **options)
