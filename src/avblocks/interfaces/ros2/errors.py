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
