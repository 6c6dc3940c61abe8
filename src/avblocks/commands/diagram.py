"""``avblocks diagram TARGET -o diagram.svg``: draw a scenario's diagram (SVG/PNG)."""

from __future__ import annotations

from ..scenarios.targets import load_any, parse_overrides


def add_parser(sub):
    dg = sub.add_parser("diagram", help="draw a scenario's diagram (SVG/PNG)")
    dg.add_argument("target")
    dg.add_argument("-o", "--output")
    dg.add_argument("--set", action="append", metavar="KEY=VALUE")
    dg.set_defaults(fn=cmd_diagram)
    return dg


def cmd_diagram(args):
    from ..viz.diagram import draw_diagram
    d, _sim, name, _movie = load_any(args.target, parse_overrides(args.set))
    out = args.output or f"{name}-diagram.svg"
    path = draw_diagram(d, out)
    print(f"wrote {path}")
    return 0
