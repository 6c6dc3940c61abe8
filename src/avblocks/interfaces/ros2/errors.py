"""Errors of the robot interface (defined in
:mod:`avblocks.interfaces.flight.errors`, shared with the drone interfaces)."""

from ..flight.errors import PreflightError, RobotError, RobotLinkError, RobotWarning

__all__ = ["RobotError", "PreflightError", "RobotLinkError", "RobotWarning"]
