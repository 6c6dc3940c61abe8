"""Paths a scenario names: confined to a folder, and a scenario's name as a folder name.

Shared by the scenario loader (files a scenario reads and writes) and the
``avblocks run`` command (its default output folder).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..core.errors import ScenarioError


def inside(path, folder, *, what, source=None, must_exist=False) -> Path:
    """``path`` resolved against ``folder``; a :class:`ScenarioError` when it
    leaves ``folder`` (absolute elsewhere, ``..``, a symbolic link out), or
    cannot name a file at all (a NUL character, longer than ``PATH_MAX``)."""
    text = str(path)
    if "\x00" in text or len(text) > 4096:
        raise ScenarioError(f"{text[:80]!r} is not a file path (a NUL character, or longer "
                            "than 4096 characters)", file=source, entry=what)
    folder = Path(folder).resolve()
    p = Path(os.path.expanduser(str(path))) if str(path).startswith("~") else Path(str(path))
    full = (folder / p).resolve()
    if full != folder and folder not in full.parents:
        raise ScenarioError(f"'{path}' is outside the folder '{folder}'",
                            file=source, entry=what,
                            hint="a scenario file may only write inside the output "
                                 "folder and read files under its own folder")
    if must_exist and not full.is_file():
        raise ScenarioError(f"'{path}' is not a file", file=source, entry=what)
    return full


def safe_name(name) -> str:
    """A scenario name made safe as one folder name (no separators, no
    leading dots): it names ``avblocks-out/<name>`` when ``--out`` is not given."""
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).lstrip(".")
    return s[:100] or "scenario"
