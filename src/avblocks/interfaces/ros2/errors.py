"""Errors of the robot interface."""

from __future__ import annotations

from ...core.errors import AvError


class RobotError(AvError):
    """Something about the robots (not the diagram) is wrong."""


class PreflightError(RobotError):
    """The check before the first command failed: a robot sends no pose,
    is outside the arena, or two robots are too close. Names the robots."""
