"""The public API survives refactors: every name in avblocks.__all__ and each
subpackage's __all__ still resolves, with the same kind and signature, as in the
snapshot ``public_api.json`` taken from the tree before the layering redesign
(commit dd7d55c); a signature may only grow compatibly (new optional
parameters after the old ones, same defaults). Run this file as a script to
rewrite the snapshot from the tree on ``PYTHONPATH`` (only when an API change
is intended)."""

from __future__ import annotations

import importlib
import inspect
import json
import pkgutil
from pathlib import Path

SNAPSHOT = Path(__file__).with_name("public_api.json")


_MODULE_REPR = __import__("re").compile(r"<module '([^']+)' from '[^']*'>")


def _stable(text: str) -> str:
    """Defaults that are modules (``xp=numpy``) without the machine's path."""
    return _MODULE_REPR.sub(r"<module '\1'>", text)


def _describe(obj) -> str:
    """A stable text for one public name: its kind and, for callables, its signature."""
    if inspect.ismodule(obj):
        return f"module {obj.__name__}"
    if inspect.isclass(obj):
        try:
            sig = str(inspect.signature(obj))
        except (TypeError, ValueError):
            sig = "(?)"
        return _stable(f"class{sig}")
    if callable(obj):
        try:
            return _stable(f"callable{inspect.signature(obj)}")
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


def _params(desc: str):
    """The parameter texts of a described signature (``None`` for a value or
    module), split at the top-level commas."""
    for kind in ("class(", "callable("):
        if desc.startswith(kind):
            body = desc[len(kind) - 1:]
            break
    else:
        return None
    depth, quote, out, cur = 0, None, [], ""
    for ch in body:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "([{":
            depth += 1
            if depth == 1:
                continue
        elif ch in ")]}":
            depth -= 1
            if depth == 0:
                break
        elif ch == "," and depth == 1:
            out.append(cur.strip())
            cur = ""
            continue
        cur += ch
    if cur.strip():
        out.append(cur.strip())
    return out


def compatible(before: str, now: str) -> bool:
    """``now`` still accepts every call ``before`` accepted: the old
    parameters in the same order with the same defaults, anything new
    optional (a default, ``*args`` or ``**kwargs``) and not placed before an
    old positional parameter."""
    if before == now:
        return True
    old, new = _params(before), _params(now)
    if old is None or new is None or before.split("(")[0] != now.split("(")[0]:
        return False
    it = iter(new)
    for p in old:
        for q in it:
            if q == p:
                break
            if not ("=" in q or q.startswith("*")):
                return False
        else:
            return False
    return all("=" in q or q.startswith("*") for q in it)


def test_compatible_signature_rule():
    assert compatible("callable(a, b=1)", "callable(a, b=1, *, c=2)")
    assert compatible("class(n, *, k=3)", "class(n, *, k=3, method='auto')")
    assert not compatible("callable(a, b=1)", "callable(a, b=2)")
    assert not compatible("callable(a, b=1)", "callable(a, c, b=1)")
    assert not compatible("callable(a, b=1)", "callable(a)")
    assert not compatible("class(a)", "callable(a)")


#: changes made on purpose, each with its reason: "package.name" -> (old text, new text)
INTENDED = {
    # issue 22: the default safety filter must not jam the Robotarium swap
    # (the joint QP, now traceable, is the default)
    "avblocks.controllers.CollisionAvoidance": ("mode='agent'", "mode='joint'"),
    # issue 43: Crazyflies land to 0.03 m, as Crazyswarm2's examples do (was 0.0)
    "avblocks.interfaces.crazyflie.CrazyflieLink": ("land_height=0.0", "land_height=0.03"),
    "avblocks.interfaces.crazyflie.Crazyflies": ("land_height=0.0", "land_height=0.03"),
    "avblocks.interfaces.crazyflie.Guard": ("land_height=0.0", "land_height=0.03"),
}


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
            elif not compatible(_stable(desc).replace(
                    *INTENDED.get(f"{pkg}.{name}", ("", ""))), _stable(got)):
                problems.append(f"{pkg}.{name}: was {desc!r}, now {got!r}")
    assert not problems, "\n".join(problems)


def test_every_public_package_is_in_the_snapshot():
    """A package with an ``__all__`` that imports here is guarded too: a new
    subpackage's names enter the snapshot when it is added (run this file
    as a script, or add its entry), not after a refactor broke them."""
    before = json.loads(SNAPSHOT.read_text())
    missing = sorted(set(snapshot()) - set(before))
    assert not missing, f"not in {SNAPSHOT.name}: {missing}"


if __name__ == "__main__":
    SNAPSHOT.write_text(json.dumps(snapshot(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {SNAPSHOT}")
