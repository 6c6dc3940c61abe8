"""``avblocks mavlink emulate`` and ``avblocks run ... --robots mavlink``
(the ``mavlink`` entry of :data:`avblocks.interfaces.flight.cli.FLEETS`)."""

from __future__ import annotations

import json

CONNECT_HELP = (
    "how to reach each vehicle: pymavlink connection strings, comma separated, or "
    "PREFIX:PORT+ (consecutive ports) / PREFIX:PORT+STEP for N vehicles. "
    "PX4 SITL (instance i sends to UDP 14540+i): udpin:127.0.0.1:14540+ (the default; "
    "also the emulator's PX4 layout); PX4 on another computer: udpin:0.0.0.0:14540+ "
    "(listens on every interface: name the address on purpose). ArduPilot SITL "
    "(instance i serves TCP 5760+10i): tcp:127.0.0.1:5760+10. A telemetry radio: "
    "serial:/dev/ttyUSB0:57600 (one radio per vehicle, comma separated).")


def add_commands(sub):
    """The ``mavlink`` command group."""
    return add_emulate_parser(sub)


def add_run_options(r):
    """The MAVLink options of ``avblocks run``."""
    g = r.add_argument_group("MAVLink drones (--robots mavlink; extra [mavlink])")
    g.add_argument("--mavlink-connect", default="udpin:127.0.0.1:14540+",
                   dest="mavlink_connect", metavar="CONNECTIONS", help=CONNECT_HELP)
    g.add_argument("--mavlink-names", default=None, dest="mavlink_names",
                   help="vehicle names, comma separated (default uav1, uav2, ...)")
    g.add_argument("--mavlink-origins", default=None, dest="mavlink_origins",
                   metavar="JSON",
                   help="JSON (N, 3): world (ENU) position of each vehicle's local NED "
                        "origin [m] (PX4 SITL: each spawn position; default: all at 0)")
    g.add_argument("--mavlink-rate", type=float, default=20.0, dest="mavlink_rate",
                   metavar="HZ", help="set-point stream rate per vehicle [Hz] (PX4 needs "
                                      "> 2; a 57600 baud radio carries ~20 Hz for 3 "
                                      "vehicles)")
    g.add_argument("--mavlink-telemetry-rate", type=float, default=30.0,
                   dest="mavlink_telemetry_rate", metavar="HZ",
                   help="rate asked for LOCAL_POSITION_NED and ATTITUDE_QUATERNION [Hz]")
    g.add_argument("--mavlink-ekf-origin", default=None, dest="mavlink_ekf_origin",
                   metavar="LAT,LON,ALT",
                   help="ArduPilot without GPS (indoors): send SET_GPS_GLOBAL_ORIGIN "
                        "(degrees, degrees, m AMSL) to every vehicle before preflight")
    g.add_argument("--mavlink-allow-unsafe-failsafe", action="store_true",
                   dest="mavlink_allow_unsafe_failsafe",
                   help="fly vehicles whose own loss action would leave them flying "
                        "(COM_OBL_RC_ACT 0/1/2/5, FS_GCS_ENABLE 0): only with a pilot "
                        "ready on each vehicle's RC")


def make_fleet(args, model, flight):
    """A :class:`~.drones.Drones` block standing in for ``model``."""
    from .drones import Drones
    n = model.output_ports["position"].shape[0]
    origins = json.loads(args.mavlink_origins) if args.mavlink_origins else None
    ekf = getattr(args, "mavlink_ekf_origin", None)
    if ekf:
        ekf = [float(s) for s in ekf.split(",")]
    return Drones(args.mavlink_connect, names=args.mavlink_names, n=n, origins=origins,
                  stream_rate=getattr(args, "mavlink_rate", 20.0),
                  telemetry_rate=getattr(args, "mavlink_telemetry_rate", 30.0),
                  ekf_origin=ekf,
                  allow_unsafe_failsafe=getattr(args, "mavlink_allow_unsafe_failsafe",
                                                False),
                  **flight)


# ------------------------------------------------------------------ the emulator
def _faults(items, cast=float):
    """``["2@1.5s", "3@0"]`` -> ``{2: 1.5, 3: 0.0}`` (system id @ value)."""
    from ...core.errors import ParameterError
    out = {}
    for it in items or []:
        for part in str(it).split(","):
            if not part.strip():
                continue
            try:
                sid, v = part.split("@", 1)
                out[int(sid)] = cast(float(v.strip().rstrip("s")))
            except ValueError:
                raise ParameterError("a fault is SYSID@VALUE, e.g. 2@1.5s",
                                     found=part) from None
    return out


def _ids(text):
    return [int(s) for s in (text or "").split(",") if s.strip()]


def _params(items):
    from ...core.errors import ParameterError
    out = {}
    for it in items or []:
        try:
            k, v = it.split("=", 1)
            out[k.strip()] = float(v)
        except ValueError:
            raise ParameterError("a parameter is NAME=VALUE, e.g. COM_OBL_RC_ACT=4",
                                 found=it) from None
    return out


def _deny(items):
    out = {}
    for it in items or []:
        sid, names = it.split(":", 1)
        out.setdefault(int(sid), []).extend(s.strip() for s in names.split(",") if s.strip())
    return out


def emulator_kwargs(args):
    """The :class:`~.emulator.Emulator` keyword arguments of ``args``."""
    pose0 = json.loads(args.pose0) if args.pose0 else None
    batt = json.loads(args.battery) if args.battery.strip().startswith("[") \
        else float(args.battery)
    base = args.base_port
    if base is None:
        base = 5760 if (args.link or ("udp" if args.flavor == "px4" else "tcp")) == "tcp" \
            else 14540
    return dict(n=args.n, pose0=pose0, spacing=args.spacing, flavor=args.flavor,
                base_port=base, host=args.host, link=args.link,
                vehicle_port=args.vehicle_port, battery=batt,
                offboard_timeout=args.offboard_timeout,
                offboard_loss_action=args.offboard_loss_action,
                guided_timeout=args.guided_timeout, gcs_timeout=args.gcs_timeout,
                gcs_loss_action=args.gcs_loss_action, origin=args.origin,
                silent=_faults(args.silent), stale=_faults(args.stale),
                no_pose=_ids(args.no_pose), log=args.log, pose_message=args.pose_message,
                params=_params(args.param), factory_defaults=args.factory_defaults,
                gimbal=args.gimbal, temp_reject=_faults(args.temp_reject, int),
                in_progress=_faults(args.in_progress), deny_interval=_deny(args.deny_interval),
                no_interval=_ids(args.no_interval), indoor=args.indoor)


def main(args):
    """``avblocks mavlink emulate``: run the emulator in the foreground."""
    from .._emulator import run_emulator
    from .emulator import Emulator
    em = Emulator(**emulator_kwargs(args))
    where = (f"udp {em.host}:{em.ports[0]}..{em.ports[-1]} (connect udpin:{em.host}:"
             f"{em.ports[0]}+; the vehicles send from {em.vehicle_ports[0]}.."
             f"{em.vehicle_ports[-1]})" if em.link_kind == "udp" else
             f"tcp {em.host}:{em.ports[0]}..{em.ports[-1]} (connect tcp:{em.host}:"
             f"{em.ports[0]}+10)")
    return run_emulator(em, f"emulating {em.n} {em.flavor} vehicle(s) on {where}",
                        args.duration)


def add_emulate_parser(sub):
    """``avblocks mavlink emulate`` on the ``avblocks`` sub-parsers."""
    from .emulator import ACTIONS, FLAVORS, LINKS
    r = sub.add_parser("mavlink", help="MAVLink drone tools (emulate PX4/ArduPilot)")
    rs = r.add_subparsers(dest="mavlink_command", required=True)
    e = rs.add_parser(
        "emulate", help="emulate N PX4 or ArduPilot multicopters",
        description="N emulated multicopters reached as their SITL is: PX4 (UDP: "
                    "vehicle i sends from 14580+i to 14540+i; connect "
                    "udpin:127.0.0.1:14540+) or ArduPilot (TCP server on 5760+10i; "
                    "connect tcp:127.0.0.1:5760+10). Binds 127.0.0.1 unless --host "
                    "names another address.")
    e.add_argument("--n", type=int, default=1, help="number of vehicles")
    e.add_argument("--flavor", default="px4", choices=list(FLAVORS))
    e.add_argument("--link", default=None, choices=list(LINKS),
                   help="udp (PX4's default) or tcp (ArduPilot's default)")
    e.add_argument("--host", default="127.0.0.1",
                   help="address the vehicles bind and send to (default 127.0.0.1)")
    e.add_argument("--base-port", type=int, default=None, dest="base_port",
                   help="udp: the commander's ports base_port+i (default 14540); tcp: "
                        "vehicle i listens on base_port+10i (default 5760)")
    e.add_argument("--vehicle-port", type=int, default=None, dest="vehicle_port",
                   help="udp: vehicle i's own port vehicle_port+i (default base port + "
                        "40: 14580, as PX4 SITL)")
    e.add_argument("--pose0", help="JSON list of [x, y, z] start positions (ENU) [m] "
                                   "(default: on the floor along x, centred on 0, "
                                   "--spacing apart: drone_formation's start line)")
    e.add_argument("--spacing", type=float, default=1.0,
                   help="without --pose0: vehicles on a line this far apart [m]")
    e.add_argument("--battery", default="1.0",
                   help="start charge (fraction), one or a JSON list per vehicle")
    e.add_argument("--offboard-timeout", type=float, default=0.5, dest="offboard_timeout",
                   help="PX4 COM_OF_LOSS_T [s]")
    e.add_argument("--offboard-loss-action", default="land", choices=list(ACTIONS),
                   dest="offboard_loss_action", help="PX4 COM_OBL_RC_ACT (4, 5, 3)")
    e.add_argument("--guided-timeout", type=float, default=3.0, dest="guided_timeout",
                   help="ArduPilot GUID_TIMEOUT [s]")
    e.add_argument("--gcs-timeout", type=float, default=5.0, dest="gcs_timeout",
                   help="ArduPilot FS_GCS_TIMEOUT [s]")
    e.add_argument("--gcs-loss-action", default="land", choices=list(ACTIONS),
                   dest="gcs_loss_action", help="ArduPilot FS_GCS_ENABLE (5, 7, 1)")
    e.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="set an autopilot parameter on every vehicle (repeatable)")
    e.add_argument("--factory-defaults", action="store_true", dest="factory_defaults",
                   help="fail-safe parameters at the firmware's defaults (PX4 "
                        "COM_OBL_RC_ACT 0, ArduPilot FS_GCS_ENABLE 0), not as "
                        "docs/drones.md configures them")
    e.add_argument("--gimbal", action="store_true",
                   help="each vehicle also has a gimbal component sending heartbeats")
    e.add_argument("--indoor", action="store_true",
                   help="ArduPilot without GPS: no local position until "
                        "SET_GPS_GLOBAL_ORIGIN")
    e.add_argument("--origin", default="world", choices=["world", "start"],
                   help="local NED origin: the world origin or each vehicle's start")
    e.add_argument("--silent", action="append", metavar="SYSID@T",
                   help="the vehicle sends nothing from T s after its first set-point")
    e.add_argument("--stale", action="append", metavar="SYSID@T",
                   help="the vehicle stops sending positions T s after its first set-point")
    e.add_argument("--no-pose", dest="no_pose", metavar="SYSID,...",
                   help="vehicles that never have a position")
    e.add_argument("--temp-reject", action="append", dest="temp_reject", metavar="SYSID@N",
                   help="its first N mode changes and armings are TEMPORARILY_REJECTED")
    e.add_argument("--in-progress", action="append", dest="in_progress", metavar="SYSID@S",
                   help="mode, arm and takeoff answered IN_PROGRESS, finally after S s")
    e.add_argument("--deny-interval", action="append", dest="deny_interval",
                   metavar="SYSID:MSG[,MSG]",
                   help="SET_MESSAGE_INTERVAL for these messages is DENIED")
    e.add_argument("--no-interval", dest="no_interval", metavar="SYSID,...",
                   help="vehicles without SET_MESSAGE_INTERVAL (UNSUPPORTED)")
    e.add_argument("--pose-message", default="local", choices=["local", "odometry"],
                   dest="pose_message", help="PX4's default stream: LOCAL_POSITION_NED + "
                                             "ATTITUDE_QUATERNION, or ODOMETRY")
    e.add_argument("--duration", type=float, help="seconds to run (default: forever)")
    e.add_argument("--log", help="JSON-lines log (raw received messages, events)")
    e.set_defaults(fn=main)
    return r
