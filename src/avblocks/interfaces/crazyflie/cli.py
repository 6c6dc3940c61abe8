"""``avblocks crazyflies emulate`` / ``guard`` and ``avblocks run ... --robots crazyflies``
(the ``crazyflies`` entry of :data:`avblocks.interfaces.flight.cli.FLEETS`)."""

from __future__ import annotations


def add_commands(sub):
    """The ``crazyflies`` command group."""
    from .emulator import add_parser
    return add_parser(sub)


def add_run_options(r):
    """The Crazyflie options of ``avblocks run``."""
    g = r.add_argument_group("Crazyflies (--robots crazyflies; extra [crazyflie])")
    g.add_argument("--cf-router", default="tcp/127.0.0.1:7447", dest="cf_router",
                   help="Zenoh router of the Crazyswarm2 setup (rmw_zenoh)")
    g.add_argument("--cf-names", default=None, dest="cf_names",
                   help="vehicle names as in crazyflies.yaml, comma separated, in agent "
                        "order (default cf1, cf2, ...)")
    g.add_argument("--cf-setpoint", default="full_state", dest="cf_setpoint",
                   choices=["full_state", "velocity"],
                   help="stream /cfN/cmd_full_state or /cfN/cmd_velocity_world")
    g.add_argument("--cf-arm", default="auto", choices=["auto", "yes", "no"], dest="cf_arm",
                   help="/cfN/arm before takeoff: auto (the vehicles whose status says "
                        "they need it: Crazyflie 2.1 Brushless), yes (every vehicle), no")
    g.add_argument("--cf-pose-source", default="pose", choices=["pose", "mocap"],
                   dest="cf_pose_source",
                   help="positions from /cfN/pose or the motion-capture /poses")
    g.add_argument("--cf-land-height", type=float, default=0.03, dest="cf_land_height",
                   help="height the landing ends at [m] (default 0.03, as Crazyswarm2's "
                        "examples)")


def make_fleet(args, model, flight):
    """A :class:`~.block.Crazyflies` block standing in for ``model``."""
    from ...core.errors import ParameterError
    from .block import Crazyflies
    n = model.output_ports["position"].shape[0]
    names = (args.cf_names.split(",") if getattr(args, "cf_names", None)
             else [f"cf{k + 1}" for k in range(n)])
    if len(names) != n:
        raise ParameterError(f"the scenario flies {n} vehicles but {len(names)} Crazyflie "
                             f"names were given", param="cf-names", found=names)
    arm = {"auto": "auto", "yes": True, "no": False}[getattr(args, "cf_arm", "auto")]
    return Crazyflies(names, getattr(args, "cf_router", "tcp/127.0.0.1:7447"),
                      setpoint=getattr(args, "cf_setpoint", "full_state"), arm=arm,
                      pose_source=getattr(args, "cf_pose_source", "pose"),
                      land_height=getattr(args, "cf_land_height", 0.03), **flight)
