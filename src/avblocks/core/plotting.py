"""Plotting backends: how data-level objects draw without importing the layers that draw.

:meth:`Results.plot`, :meth:`Results.animate` and :meth:`Diagram.to_graphviz`
are conveniences of the core layer whose work is done by a layer above it
(:mod:`avblocks.viz`). They find that layer the way pandas finds its plotting
backend: by *name*, in a registry the backend fills when it is imported. The
core never imports the backend's code; it asks :func:`get_backend` for the
module registered under ``options["backend"]`` (``"avblocks.viz"`` by
default), importing that module by name the first time if nobody has yet.

A backend is any object with the functions the conveniences call:
``plot_trajectories(results, ax=None, **options)``,
``plot_signals(results, signals, **options)``, ``animate(results, **options)``,
``to_dot(diagram)`` and ``diagram_svg(diagram)`` (the picture Jupyter shows
for a :class:`~avblocks.core.diagram.Diagram`).

>>> from avblocks.core import plotting
>>> plotting.options["backend"]
'avblocks.viz'
"""

from __future__ import annotations

import importlib

from .errors import AvError

#: ``backend``: the name looked up by the conveniences (a registered name or
#: an importable module that registers itself, like pandas' ``plotting.backend``)
options = {"backend": "avblocks.viz"}

_BACKENDS: dict[str, object] = {}


def register_backend(name: str, backend) -> None:
    """Make ``backend`` (a module or object) available under ``name``."""
    _BACKENDS[str(name)] = backend


def get_backend(name: str | None = None):
    """The backend registered under ``name`` (default ``options["backend"]``),
    importing the module of that name first if it has not registered yet."""
    name = options["backend"] if name is None else str(name)
    found = _BACKENDS.get(name)
    if found is None:
        try:
            module = importlib.import_module(name)
        except ImportError as e:
            raise AvError(f"plotting backend {name!r} is not available",
                          found=name, hint="install avblocks' plotting dependencies "
                                           "(Matplotlib) or set avblocks.core.plotting."
                                           "options['backend']") from e
        found = _BACKENDS.setdefault(name, module)
    return found
