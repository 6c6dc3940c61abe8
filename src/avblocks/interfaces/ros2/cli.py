"""Command-line hooks: ``avblocks robots emulate`` and
``avblocks run <scenario> --robots tb1,tb2,tb3``."""

from __future__ import annotations


def add_commands(sub):
    """Add the ``robots`` command group."""
    from ..flight.cli import add_commands as add_drone_commands
    from .emulator import add_parser
    r = add_parser(sub)
    add_drone_commands(sub)       # avblocks mavlink ... (interfaces.flight.cli.FLEETS)
    return r


def add_run_options(r):
    """Options of ``avblocks run`` that put the scenario on robots."""
    g = r.add_argument_group("robots (extra [ros2])")
    g.add_argument("--robots", help="run on these ROS 2 robots instead of the model, "
                                    "e.g. tb1,tb2,tb3 (agent order); or on drones: "
                                    "'mavlink' or 'crazyflies' (see the drones options)")
    g.add_argument("--transport", default="bridge", choices=["bridge", "rmw_zenoh", "rclpy"],
                   help="zenoh-bridge-ros2dds keys, rmw_zenoh keys, or rclpy")
    g.add_argument("--router", default="tcp/127.0.0.1:7447", help="Zenoh router endpoint")
    g.add_argument("--replace", default=None,
                   help="name of the block to replace (default 'fleet' or the first "
                        "vehicle model)")
    g.add_argument("--robot-timeout", type=float, default=0.5, dest="robot_timeout",
                   help="watchdog timeout [s]")
    g.add_argument("--robot-give-up", type=float, default=10.0, dest="robot_give_up",
                   help="no pose from any robot for this long [s]: stop every robot, "
                        "save the results so far and exit 3")
    g.add_argument("--pose-source", default="odom", choices=["odom", "mocap"],
                   dest="pose_source")
    from ..flight.cli import add_run_options as add_drone_options
    add_drone_options(r)


def apply(args, diagram, sim):
    """Swap the model block for robots when ``--robots`` is given. A run on
    robots is paced: ``realtime`` defaults to 1, and the block's
    ``time_scale`` follows it (an emulator run with the same factor)."""
    if not getattr(args, "robots", None):
        return None
    from ..flight.cli import FLEETS
    if args.robots in FLEETS:     # drones: interfaces.flight.cli
        from ..flight.cli import apply as fly
        return fly(args, diagram, sim)
    from .swap import _find_model, replace_block, robots_like
    name = args.replace or ("fleet" if "fleet" in diagram.blocks else _find_model(diagram))
    sim.setdefault("realtime", 1.0)
    if sim["realtime"] is None:
        sim["realtime"] = 1.0
    if name is None or name not in diagram.blocks:
        replace_block(diagram, name, None)      # raises the clear error
    robots = robots_like(diagram[name].block, args.robots, pose=args.pose_source,
                         transport=args.transport, router=args.router,
                         timeout=args.robot_timeout,
                         give_up=getattr(args, "robot_give_up", 10.0),
                         time_scale=float(sim["realtime"]))
    replace_block(diagram, name, robots)
    return robots


def report(res):
    """One line about pacing: overruns and worst lateness of a paced run."""
    m = res.meta
    if "overruns" not in m:
        return None
    steps = max(int(m.get("steps", 0)), 1)
    return (f"paced         {m['overruns']} of {steps} steps overran, worst lateness "
            f"{1e3 * m['max_lateness']:.1f} ms")
