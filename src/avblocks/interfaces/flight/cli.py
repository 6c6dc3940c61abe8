"""``avblocks run <scenario> --robots mavlink`` (or ``crazyflies``): fly a
scenario's velocity-controlled quadrotors on drones, and the drone
emulators' commands.

Each protocol registers ONE entry in :data:`FLEETS`: the keyword of
``--robots`` -> the module that implements it. That module provides

* ``add_run_options(group)``: its own options of ``avblocks run``
  (prefixed with its name, e.g. ``--mavlink-connect``);
* ``add_commands(sub)``: its command group (e.g. ``avblocks mavlink
  emulate``);
* ``make_fleet(args, model, flight)`` -> a :class:`~.fleet.Fleet` block with
  the ports of ``model`` (the block it replaces), built with ``flight``,
  the shared keyword arguments of :func:`flight_options`.

The modules are imported by name only when used, so this package does not
depend on the protocol packages above it.
"""

from __future__ import annotations

import importlib

#: ``--robots`` keyword -> module implementing it (see the module docstring).
FLEETS = {
    "mavlink": "avblocks.interfaces.mavlink.cli",
    "crazyflies": "avblocks.interfaces.crazyflie.cli",
}


def _module(key):
    return importlib.import_module(FLEETS[key])


def _available():
    out = []
    for key in FLEETS:
        try:
            out.append((key, _module(key)))
        except ImportError:     # a protocol package not there (yet)
            continue
    return out


#: An argument that starts with a minus and a digit (or ".digit") is a
#: value, not an option: Python 3.13's argparse rule, which 3.11 and 3.12
#: lack (they take only a plain negative number), so that the documented
#: ``--geofence -4,4,-3,5,0,3`` parses.
NEGATIVE_VALUE = r"^-\.?\d"


def add_run_options(r):
    """The shared flight options of ``avblocks run`` and each protocol's own."""
    import re
    if hasattr(r, "_negative_number_matcher"):
        r._negative_number_matcher = re.compile(NEGATIVE_VALUE)
    g = r.add_argument_group("drones (--robots " + " | ".join(FLEETS) + ")")
    g.add_argument("--takeoff-height", type=float, default=None, dest="takeoff_height",
                   help="takeoff height [m] (default: the start height of the "
                        "scenario's vehicles, or 1 m)")
    g.add_argument("--geofence", default=None,
                   help="xmin,xmax,ymin,ymax,zmin,zmax [m] (default: none)")
    g.add_argument("--min-separation", type=float, default=0.0, dest="min_separation",
                   help="smallest distance between vehicles [m]")
    g.add_argument("--speed-max", type=float, default=None, dest="speed_max",
                   help="speed limit [m/s] (default: the model's, else 1)")
    g.add_argument("--accel-max", type=float, default=float("inf"), dest="accel_max",
                   help="set-point change limit [m/s^2]")
    g.add_argument("--battery-min", type=float, default=0.2, dest="battery_min",
                   help="refuse to start below this charge (fraction)")
    g.add_argument("--flight-log", default=None, dest="flight_log",
                   help="JSON-lines flight log (default: flight-log.jsonl in --out)")
    g.add_argument("--failsafe", default="land", choices=["land", "rtl"])
    g.add_argument("--slot-tolerance", type=float, default=0.5, dest="slot_tolerance",
                   help="pre-flight: the vehicles are matched to the scenario's start "
                        "positions by where they stand; refuse one further than this "
                        "from its start [m] (default 0.5; inf: any placement)")
    for _, mod in _available():
        mod.add_run_options(r)


def add_commands(sub):
    """Each protocol's command group (``avblocks mavlink emulate`` ...)."""
    for _, mod in _available():
        mod.add_commands(sub)


def flight_options(args, start_height=None):
    """The shared :class:`~.fleet.Fleet` keyword arguments from ``args``."""
    from pathlib import Path
    h = getattr(args, "takeoff_height", None)
    if h is None:
        h = start_height if start_height is not None and start_height > 0.05 else 1.0
    fence = getattr(args, "geofence", None)
    if isinstance(fence, str):
        from ...core.errors import ParameterError
        try:
            fence = [float(s) for s in fence.split(",")]
        except ValueError:
            raise ParameterError("--geofence is six numbers: xmin,xmax,ymin,ymax,zmin,zmax",
                                 param="geofence", found=fence) from None
    log = getattr(args, "flight_log", None)
    if log is None and getattr(args, "out", None):
        Path(args.out).mkdir(parents=True, exist_ok=True)
        log = str(Path(args.out) / "flight-log.jsonl")
    kw = {"takeoff_height": float(h), "geofence": fence,
          "min_separation": getattr(args, "min_separation", 0.0),
          "accel_max": getattr(args, "accel_max", float("inf")),
          "battery_min": getattr(args, "battery_min", 0.2), "log": log,
          "failsafe": getattr(args, "failsafe", "land")}
    if getattr(args, "speed_max", None) is not None:
        kw["speed_max"] = args.speed_max
    return kw


def start_line(n, spacing=1.0):
    """The emulators' default start positions (n, 3): on the floor, along x,
    centred on 0, ``spacing`` apart: where the drone_formation scenario
    starts n agents (its ``start_positions``), so that an emulator started
    with n vehicles passes the start-slot pre-flight of ``avblocks run
    drone_formation --set agents=n``."""
    import numpy as np

    from ...core.errors import ParameterError
    if not np.isfinite(spacing):
        raise ParameterError("spacing must be a finite distance [m]", param="spacing",
                             found=spacing)
    x = (np.arange(int(n)) - (int(n) - 1) / 2) * float(spacing)
    return np.column_stack([x, np.zeros(len(x)), np.zeros(len(x))])


def model_start(model):
    """Start positions (N, 3) of a velocity-controlled quadrotor subsystem
    or a 3-D SingleIntegrator (None when not found)."""
    import numpy as np
    blocks = [model]
    if hasattr(model, "blocks"):
        blocks = [h.block for h in model.blocks.values()]
    for b in blocks:
        try:
            x0 = b.initial_state()
        except Exception:  # noqa: BLE001 - not a block with a state
            continue
        p = x0.get("position") if isinstance(x0, dict) else None
        if p is not None and np.ndim(p) == 2 and np.shape(p)[1] == 3:
            return np.asarray(p, float)
    return None


def apply(args, diagram, sim):
    """Swap the scenario's quadrotors for the fleet named by ``--robots``.
    The run is paced (``realtime`` 1)."""
    import numpy as np

    from ...core.errors import ParameterError
    from .swap import find_flyer, replace_block
    key = args.robots
    name = getattr(args, "replace", None) or find_flyer(diagram)
    if name is None or name not in diagram.blocks:
        replace_block(diagram, name, None)      # raises the clear error
    try:
        mod = _module(key)
    except ImportError as e:
        raise ParameterError(f"the '{key}' interface is not available ({e})",
                             param="robots", hint="install the extra it needs") from None
    if sim.get("realtime") not in (None, 1, 1.0):
        raise ParameterError("drones fly in real time", param="realtime",
                             expected=1.0, found=sim.get("realtime"))
    sim["realtime"] = 1.0
    model = diagram[name].block
    p0 = model_start(model)
    flight = flight_options(args, None if p0 is None else float(np.median(p0[:, 2])))
    if p0 is not None:          # fly the vehicles where they stand (pre-flight)
        flight["slots"] = p0
        flight["slot_tolerance"] = getattr(args, "slot_tolerance", 0.5)
    fleet = mod.make_fleet(args, model, flight)
    replace_block(diagram, name, fleet)
    return fleet
