"""Errors of the robot interface."""

from __future__ import annotations

from ...core.errors import AvError, SimulationError, SimulationWarning


class RobotError(AvError):
    """Something about the robots (not the diagram) is wrong."""


class PreflightError(RobotError):
    """The check before the first command failed: a robot sends no pose,
    is outside the arena, or two robots are too close. Names the robots."""


class RobotLinkError(SimulationError, RobotError):
    """No robot was heard for ``give_up`` seconds (router or network down):
    every robot was commanded zero and the run ended; ``results`` holds the
    log up to then."""


class RobotWarning(SimulationWarning):
    """Robot traffic that was ignored (malformed payloads on a pose topic);
    names the robot and the topic."""


class FlightError(RobotError):
    """A vehicle refused or did not acknowledge a command (arming, a mode
    change, takeoff) in time; names the vehicle, the command and the
    reason the vehicle gave."""


class FailsafeError(SimulationError, RobotError):
    """The fail-safe ended the run: every vehicle was commanded to land
    (LAND/RTL) first, then the run stopped. ``reason`` says why (a NaN in
    the commands, a stale pose, a vehicle that stopped answering, a limit
    broken in flight), ``vehicles`` which; ``results`` holds the log up to
    then."""

    def __init__(self, message, *, reason=None, vehicles=(), **kw):
        super().__init__(message, **kw)
        self.reason = reason
        self.vehicles = list(vehicles)


class LimitError(FailsafeError):
    """The fail-safe ended the run because a flight limit was broken in
    flight (a vehicle outside the geofence by more than the margin, two
    vehicles closer than the minimum separation); names the vehicles."""
