"""``avblocks list [--blocks] [--json]``: the built-in scenarios and their
parameters, or block types; as text, or as one JSON document for scripts::

    avblocks list --json            # [{"name", "kind", "description", "parameters"}]
    avblocks list --blocks --json   # [{"type", "summary"}]
"""

from __future__ import annotations

import importlib
import inspect


def add_parser(sub):
    li = sub.add_parser("list", help="list built-in scenarios (or --blocks)")
    li.add_argument("--blocks", action="store_true", help="list block types instead")
    li.add_argument("--json", action="store_true",
                    help="print one JSON document (a list of objects) instead of text")
    li.set_defaults(fn=cmd_list)
    return li


def _summary(cls) -> str:
    """A class's one-line summary: its docstring's first sentence."""
    para = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
    cut = para.find(". ")
    return para[:cut + 1] if cut >= 0 else para


def scenarios():
    """``[{"name", "kind", "description", "parameters"}]`` of the built-in scenarios."""
    from ..scenarios import builtin_scenarios, load_scenario
    out = []
    for name, path in builtin_scenarios().items():
        if path.suffix == ".py":
            mod = importlib.import_module(f"avblocks.scenarios.{name}")
            desc = (mod.__doc__ or "").strip().split("\n\n")[0]
            sig = inspect.signature(mod.make_diagram)
            params = {k: v.default for k, v in sig.parameters.items()}
        else:
            sc = load_scenario(name)
            desc = sc.description
            params = dict(sc.data.get("parameters") or {})
        out.append({"name": name, "kind": path.suffix.lstrip("."),
                    "description": " ".join(desc.split()), "parameters": params})
    return out


def blocks():
    """``[{"type", "summary"}]`` of the block types, sorted."""
    from ..scenarios import block_registry
    return [{"type": k, "summary": _summary(cls)}
            for k, cls in sorted(block_registry(code_blocks=True, interfaces=True).items())]


def cmd_list(args):
    import json
    rows = blocks() if args.blocks else scenarios()
    if getattr(args, "json", False):
        print(json.dumps(rows, indent=1, default=repr))
        return 0
    if args.blocks:
        for row in rows:
            print(f"{row['type']:40s} {row['summary']}")
        return 0
    for row in rows:
        params = ", ".join(f"{k}={v}" for k, v in row["parameters"].items())
        print(f"{row['name']}\n    {row['description']}\n    parameters: {params}")
    return 0
