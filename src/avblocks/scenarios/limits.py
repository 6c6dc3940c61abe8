"""Limits on what a scenario may ask for: file size, YAML expansion, memory."""

from __future__ import annotations

import os

from ..core.errors import ParameterError, ScenarioError

#: Largest scenario file read (bytes).
MAX_FILE_BYTES = 10 * 1024**2
#: Largest number of values a YAML document may expand to through
#: anchors and aliases (a "billion laughs" file is refused, not expanded).
MAX_YAML_VALUES = 1_000_000


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
