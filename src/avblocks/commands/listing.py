"""``avblocks list [--blocks]``: the built-in scenarios and their parameters, or block types."""

from __future__ import annotations

import importlib
import inspect


def add_parser(sub):
    li = sub.add_parser("list", help="list built-in scenarios (or --blocks)")
    li.add_argument("--blocks", action="store_true", help="list block types instead")
    li.set_defaults(fn=cmd_list)
    return li


def _summary(cls) -> str:
    """A class's one-line summary: its docstring's first sentence."""
    para = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
    cut = para.find(". ")
    return para[:cut + 1] if cut >= 0 else para


def cmd_list(args):
    from ..scenarios import block_registry, builtin_scenarios, load_scenario
    if args.blocks:
        for k, cls in sorted(block_registry(code_blocks=True).items()):
            print(f"{k:40s} {_summary(cls)}")
        return 0
    for name, path in builtin_scenarios().items():
        if path.suffix == ".py":
            mod = importlib.import_module(f"avblocks.scenarios.{name}")
            desc = (mod.__doc__ or "").strip().split("\n\n")[0]
            sig = inspect.signature(mod.make_diagram)
            params = ", ".join(f"{k}={v.default}" for k, v in sig.parameters.items())
        else:
            sc = load_scenario(name)
            desc = sc.description
            params = ", ".join(f"{k}={v}" for k, v in
                               (sc.data.get("parameters") or {}).items())
        print(f"{name}\n    {' '.join(desc.split())}\n    parameters: {params}")
    return 0
