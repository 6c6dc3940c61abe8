"""``avblocks mavlink emulate`` and ``avblocks run ... --robots mavlink``
(the ``mavlink`` entry of :data:`avblocks.interfaces.flight.cli.FLEETS`)."""

from __future__ import annotations


def add_commands(sub):
    """The ``mavlink`` command group."""
    from .emulator import add_parser
    return add_parser(sub)


def add_run_options(r):
    """The MAVLink options of ``avblocks run``."""
    g = r.add_argument_group("MAVLink drones (--robots mavlink; extra [mavlink])")
    g.add_argument("--mavlink-connect", default="udpout:127.0.0.1:14540+",
                   dest="mavlink_connect",
                   help="one pymavlink connection string per vehicle, comma separated, "
                        "or PREFIX:PORT+ for consecutive ports (default "
                        "udpout:127.0.0.1:14540+, the emulator's)")
    g.add_argument("--mavlink-names", default=None, dest="mavlink_names",
                   help="vehicle names, comma separated (default uav1, uav2, ...)")
    g.add_argument("--mavlink-origins", default=None, dest="mavlink_origins",
                   help="JSON (N, 3): world position of each vehicle's local NED origin")


def make_fleet(args, model, flight):
    """A :class:`~.drones.Drones` block standing in for ``model``."""
    import json

    from .drones import Drones
    n = model.output_ports["position"].shape[0]
    origins = json.loads(args.mavlink_origins) if args.mavlink_origins else None
    return Drones(args.mavlink_connect, names=args.mavlink_names, n=n, origins=origins,
                  **flight)
