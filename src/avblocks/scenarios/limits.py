"""Limits on what a scenario may ask for: file size, YAML expansion, nesting,
text and number sizes, memory.

Every limit is checked before the value is walked by anything recursive
(the loader's substitution, ``copy.deepcopy``, the editor's YAML writer), and
every refusal is a :class:`~avblocks.core.errors.ScenarioError` naming the
file and the limit.
"""

from __future__ import annotations

import os

from ..core.errors import ParameterError, ScenarioError
from ..core.memlimit import memory_limit  # noqa: F401  (limits.memory_limit, as before)

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
#: Deepest nesting of lists and mappings in a scenario (the file's top
#: mapping is level 1). NumPy arrays have at most 64 dimensions and a
#: scenario's sections add a few levels; nothing a scenario means needs
#: more, and walkers that recurse stay far from Python's recursion limit.
MAX_DEPTH = 100
#: Longest text value (characters): names, descriptions, paths.
MAX_TEXT = 100_000
#: Longest mapping key (characters): block, parameter and section names.
MAX_KEY = 1_000
#: Most digits of a whole number (``10**100`` and beyond mean nothing here;
#: Python itself refuses to convert 4,300 digits).
MAX_DIGITS = 100


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


def budget(elements, what):
    """Refuse an array of ``elements`` float64 values past the memory limit,
    before allocating it."""
    need = 8 * int(elements)
    lim = memory_limit()
    if need > lim:
        raise ParameterError(f"{what} would take {need / 1e9:.3g} GB", param=what,
                             expected=f"<= {lim / 1e9:.3g} GB (AVBLOCKS_MAX_MEMORY)",
                             hint="use fewer agents/points")


def _too_long(v, limit, what, source, entry):
    return ScenarioError(f"{what} of {len(v):,} characters, more than {limit:,}",
                         file=source, entry=entry,
                         hint=f"starts {v[:40]!r}")


def _entry(path):
    """A readable entry for a walk's path (the first few keys)."""
    out = ""
    for k in path[:4]:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return (out or None) if len(path) <= 4 else out + "..."


def check_values(data, source=None, *, max_depth=None):
    """Refuse ``data`` (a scenario's values) past the limits, without
    recursion: nesting deeper than :data:`MAX_DEPTH`, more than
    :data:`MAX_YAML_NODES` values, text longer than :data:`MAX_TEXT`, keys
    longer than :data:`MAX_KEY`, whole numbers with more than
    :data:`MAX_DIGITS` digits. A value shared several times (a YAML alias)
    is counted each time it is used.

    Raises
    ------
    ScenarioError
        Naming ``source``, the entry and the limit.
    """
    limit = MAX_DEPTH if max_depth is None else int(max_depth)
    stack = [(data, 1, ())]
    nodes = 0
    while stack:
        v, depth, path = stack.pop()
        nodes += 1
        if nodes > MAX_YAML_NODES:
            raise ScenarioError(f"more than {MAX_YAML_NODES:,} values", file=source,
                                hint="generate large data (generators) instead of "
                                     "writing it out")
        if isinstance(v, dict | list | tuple):
            if depth > limit:
                raise ScenarioError(f"values nest deeper than {limit} levels "
                                    "(lists and mappings inside each other)",
                                    file=source, entry=_entry(path),
                                    hint="a scenario's values are numbers, text and "
                                         "lists or arrays of them")
            if isinstance(v, dict):
                for k, x in v.items():
                    if isinstance(k, str) and len(k) > MAX_KEY:
                        raise _too_long(k, MAX_KEY, "a key", source, _entry(path))
                    stack.append((x, depth + 1, (*path, k) if len(path) < 5 else path))
            else:
                stack.extend((x, depth + 1, (*path, i) if len(path) < 5 else path)
                             for i, x in enumerate(v))
        elif isinstance(v, str):
            if len(v) > MAX_TEXT:
                raise _too_long(v, MAX_TEXT, "a text", source, _entry(path))
        elif isinstance(v, int) and not isinstance(v, bool) and \
                v.bit_length() > MAX_DIGITS * 3.33:
            raise ScenarioError(f"a whole number of about {int(v.bit_length() / 3.3219):,} "
                                f"digits, more than {MAX_DIGITS}", file=source,
                                entry=_entry(path))
