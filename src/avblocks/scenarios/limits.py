"""Limits on what a scenario may ask for: file size, YAML expansion, memory."""

from __future__ import annotations

import os

from ..core.errors import ParameterError, ScenarioError

#: Largest scenario file read (bytes).
MAX_FILE_BYTES = 10 * 1024**2
#: Largest number of values a YAML document may expand to through
#: anchors and aliases (a "billion laughs" file is refused, not expanded).
MAX_YAML_VALUES = 1_000_000


#: Most blocks a scenario file may declare (``AVBLOCKS_MAX_BLOCKS`` to change).
MAX_BLOCKS = 2_000
#: Most wires a scenario file may declare.
MAX_WIRES = 20_000
#: Most YAML nodes (values, keys, lists, mappings) a scenario file may hold
#: as written; counted by libyaml before anything is built (a 10 MB file
#: of numbers parses for tens of seconds).
MAX_YAML_NODES = 1_000_000


def max_blocks() -> int:
    """:data:`MAX_BLOCKS`, or ``AVBLOCKS_MAX_BLOCKS`` when set."""
    env = os.environ.get("AVBLOCKS_MAX_BLOCKS")
    if not env:
        return MAX_BLOCKS
    try:
        n = int(env)
    except ValueError:
        raise ScenarioError(f"AVBLOCKS_MAX_BLOCKS must be a whole number, found {env!r}"
                            ) from None
    return max(n, 1)


def too_many_blocks(n, source=None, entry="blocks"):
    """The error for a scenario with ``n`` blocks, past :func:`max_blocks`."""
    lim = max_blocks()
    return ScenarioError(f"more than {lim:,} blocks" if n is None else
                         f"{n:,} blocks, more than the {lim:,} a scenario file may declare",
                         file=source, entry=entry,
                         hint="vectorize: one block serves N agents (agents are the "
                              "leading axis); or set AVBLOCKS_MAX_BLOCKS")


def memory_limit() -> int:
    """Bytes a scenario may ask for (generated arrays; the log is checked by
    ``simulate``): ``AVBLOCKS_MAX_MEMORY`` (e.g. ``8e9``) or half the
    physical memory, at most 8 GB."""
    env = os.environ.get("AVBLOCKS_MAX_MEMORY")
    if env:
        try:
            return int(float(env))
        except (ValueError, OverflowError):
            raise ScenarioError(f"AVBLOCKS_MAX_MEMORY must be a number of bytes, "
                                f"found {env!r}") from None
    try:
        phys = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        phys = 16 * 1024**3
    return int(min(8e9, phys / 2))


def budget(elements, what):
    """Refuse an array of ``elements`` float64 values past the memory limit,
    before allocating it."""
    need = 8 * int(elements)
    lim = memory_limit()
    if need > lim:
        raise ParameterError(f"{what} would take {need / 1e9:.3g} GB", param=what,
                             expected=f"<= {lim / 1e9:.3g} GB (AVBLOCKS_MAX_MEMORY)",
                             hint="use fewer agents/points")
