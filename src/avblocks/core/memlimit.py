"""How much memory one thing avblocks reads or builds may take: the limit
shared by scenario files (their generated arrays), results files, sweep
stores and trained policies, so that a small file someone sent cannot
make avblocks allocate what it declares (an array's shape, a compressed
member's size) before anything is read.

``AVBLOCKS_MAX_MEMORY`` (bytes, e.g. ``8e9``) sets it; else half the
physical memory, at most 8 GB.
"""

from __future__ import annotations

import os

from .errors import ScenarioError


def memory_limit() -> int:
    """Bytes one thing read or built may take: ``AVBLOCKS_MAX_MEMORY`` (e.g.
    ``8e9``) or half the physical memory, at most 8 GB."""
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


def too_large(need: int) -> bool:
    """Whether ``need`` bytes pass :func:`memory_limit`."""
    return int(need) > memory_limit()


def describe(need: int) -> str:
    """``"12.3 GB, more than the 8 GB limit (AVBLOCKS_MAX_MEMORY)"``."""
    return (f"{int(need) / 1e9:.3g} GB, more than the {memory_limit() / 1e9:.3g} GB "
            "limit (AVBLOCKS_MAX_MEMORY)")
