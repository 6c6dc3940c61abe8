"""File writers: how :class:`~avblocks.core.results.Results` writes formats
whose writer lives above the core layer.

:meth:`Results.to_mcap` writes an MCAP file (Foxglove's well-known schemas)
through :mod:`avblocks.foxglove`, a layer above the core with its own
extra (``mcap``, ``foxglove-sdk``). As with the plotting backends
(:mod:`avblocks.core.plotting`), the core never imports that code: it asks
:func:`get_writer` for the writer registered under a format's name, and
the first time imports the module :data:`MODULES` names for it, which
registers itself.

>>> from avblocks.core import writers
>>> writers.MODULES["mcap"]
'avblocks.foxglove'
"""

from __future__ import annotations

import importlib

from .errors import AvError

#: format -> the module that registers its writer when imported
MODULES = {"mcap": "avblocks.foxglove"}

#: format -> the extra that brings the writer's dependencies
EXTRAS = {"mcap": "foxglove"}

_WRITERS: dict[str, object] = {}


def register_writer(fmt: str, writer) -> None:
    """Make ``writer`` (an object with ``write_results(results, path,
    **options)``) the writer of format ``fmt``."""
    _WRITERS[str(fmt)] = writer


def get_writer(fmt: str):
    """The writer registered for ``fmt``, importing its module first."""
    fmt = str(fmt)
    found = _WRITERS.get(fmt)
    if found is None:
        if fmt not in MODULES:
            raise AvError("no writer for this format", expected=sorted(MODULES), found=fmt)
        try:
            importlib.import_module(MODULES[fmt])
        except ImportError as e:
            raise AvError(f"writing {fmt.upper()} files needs the '{EXTRAS[fmt]}' extra: {e}",
                          hint=f"pip install 'avblocks[{EXTRAS[fmt]}]'") from None
        found = _WRITERS.get(fmt)
        if found is None:
            raise AvError(f"the module {MODULES[fmt]!r} registered no {fmt} writer")
    return found
