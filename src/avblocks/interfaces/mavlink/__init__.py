"""PX4 and ArduPilot multicopters over MAVLink as blocks (extra
``[mavlink]``: pymavlink).

:class:`Drones` replaces ``vehicles.velocity_controlled_quadrotor`` (same
ports, plus ``fresh``/``age``) and flies N vehicles through the shared
flight layer (:mod:`avblocks.interfaces.flight`: phases, limits,
fail-safe); :class:`Emulator` (``avblocks mavlink emulate``) runs
emulated autopilots on UDP for tests; :mod:`.frames` is the one place
where NED meets the library's ENU world frame.
"""

from . import frames
from .drones import Drones, MavlinkLink, connections_from
from .emulator import Emulator, read_log

__all__ = ["Drones", "MavlinkLink", "Emulator", "frames", "connections_from", "read_log"]
