"""Moved to :mod:`avblocks.interfaces.flight._guard` (shared with the
drone interfaces); kept here so ``ros2._guard`` imports keep working."""

from ..flight._guard import _handler, _live, _stop_all, register, unregister  # noqa: F401
