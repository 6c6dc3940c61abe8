"""After-run hook of ``avblocks run``: a Python scenario module (built in or
a user's file) may define ``report(results, out_dir) -> (files, line)`` to
write its own figures or movies and return a one-line outcome, which the
command prints."""

from __future__ import annotations

import importlib
import runpy
from pathlib import Path


def run_report(target, res, out):
    """``(files, outcome line)`` from the scenario's ``report``, or ``([], None)``."""
    from . import builtin_scenarios
    p = Path(str(target))
    b = builtin_scenarios()
    if not p.is_file() and target in b and b[target].suffix == ".py":
        fn = getattr(importlib.import_module(f"avblocks.scenarios.{target}"), "report", None)
    elif p.suffix == ".py" and p.is_file():
        fn = runpy.run_path(str(p), run_name="avblocks_scenario").get("report")
    else:
        fn = None
    if fn is None:
        return [], None
    files, line = fn(res, Path(out))
    return [Path(f) for f in files], line
