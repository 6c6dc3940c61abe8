"""The public API survives refactors: every name in avblocks.__all__ and each
subpackage's __all__ still resolves, with the same kind and signature, as in the
snapshot ``public_api.json`` taken from the tree before the layering redesign
(commit dd7d55c). Run this file as a script to rewrite the snapshot from the
tree on ``PYTHONPATH`` (only when an API change is intended)."""

from __future__ import annotations

import importlib
import inspect
import json
import pkgutil
from pathlib import Path

SNAPSHOT = Path(__file__).with_name("public_api.json")


def _describe(obj) -> str:
    """A stable text for one public name: its kind and, for callables, its signature."""
    if inspect.ismodule(obj):
        return f"module {obj.__name__}"
    if inspect.isclass(obj):
        try:
            sig = str(inspect.signature(obj))
        except (TypeError, ValueError):
            sig = "(?)"
        return f"class{sig}"
    if callable(obj):
        try:
            return f"callable{inspect.signature(obj)}"
        except (TypeError, ValueError):
            return "callable(?)"
    return f"value {type(obj).__name__}"


def packages() -> list[str]:
    """avblocks and every subpackage that imports in this environment."""
    import avblocks

    names = ["avblocks"]
    for info in pkgutil.walk_packages(avblocks.__path__, "avblocks.", onerror=lambda n: None):
        if info.ispkg:
            names.append(info.name)
    return sorted(names)


def snapshot() -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for name in packages():
        try:
            mod = importlib.import_module(name)
        except Exception:  # optional extra missing here: skipped on both sides
            continue
        names = getattr(mod, "__all__", None)
        if names is None:
            continue
        out[name] = {n: _describe(getattr(mod, n)) for n in sorted(names)}
    return out


def test_public_names_and_signatures_unchanged():
    before = json.loads(SNAPSHOT.read_text())
    now = snapshot()
    problems = []
    for pkg, names in before.items():
        if pkg not in now:
            problems.append(f"{pkg}: package or its __all__ is gone")
            continue
        for name, desc in names.items():
            got = now[pkg].get(name)
            if got is None:
                problems.append(f"{pkg}.{name}: no longer in __all__")
            elif got != desc:
                problems.append(f"{pkg}.{name}: was {desc!r}, now {got!r}")
    assert not problems, "\n".join(problems)


if __name__ == "__main__":
    SNAPSHOT.write_text(json.dumps(snapshot(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {SNAPSHOT}")
