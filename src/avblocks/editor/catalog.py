"""The editor's palette: every block, generated from the blocks' own declarations.

:func:`palette` lists every public block of :func:`avblocks.scenarios.block_registry`
(and of the user's modules given with ``--blocks``) by family, each with
its summary, docstring, port table and constructor parameters, and the
generators a scenario file may use (``src/avblocks/editor/API.md``). Nothing
here names a block: the parameters come from
:meth:`avblocks.Block.constructor_parameters` (signature, numpydoc
``Parameters``, the class's ``parameter_info``), bounds and units of numeric
parameters from ``declare_parameter`` on an instance, and the ports from
:meth:`avblocks.Block.port_table` of an instance built from the block's
template (its ``example``, or derived from its required arguments) with
``$agents`` = 7 and ``$seed`` = 1.
"""

from __future__ import annotations

import inspect
import json
import math

from ..core.declarations import constructor_parameters, doc_sections, shape_text
from ..core.errors import AvError

#: Families in the palette's order (then each ``--blocks`` module).
FAMILIES = ("vehicles", "controllers", "environment", "tasks", "blocks", "viz", "interfaces")
TITLES = {"vehicles": "Vehicles", "controllers": "Controllers",
          "environment": "Environment", "tasks": "Learning tasks", "blocks": "Blocks",
          "viz": "Visualization", "interfaces": "Interfaces"}
#: The agent count the palette builds templates with (any count would do;
#: the ports are shown with the agent axis as ``N``).
TEMPLATE_AGENTS = 7
#: The parameters a new document has (the templates refer to them).
NEW_PARAMETERS = {"agents": 15, "seed": 1}


def _jsonable(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    try:
        import numpy as np
        if isinstance(v, np.generic):
            return _jsonable(v.item())
        if isinstance(v, np.ndarray):
            return _jsonable(v.tolist())
    except ImportError:  # pragma: no cover
        pass
    return None


_ROLE = None


def plain(text):
    """reStructuredText's inline markup as the page shows it: roles
    (``:class:`~avblocks.environment.World```) become their target's short
    name in single backticks, double-backtick literals single-backtick ones
    (the page draws `x` as code); anything else is kept as written."""
    import re
    global _ROLE
    if not isinstance(text, str) or "`" not in text:
        return text
    if _ROLE is None:
        _ROLE = re.compile(r":[A-Za-z][\w:+.-]*:`([^`]+)`")

    def role(m):
        t = m.group(1).strip()
        label = re.match(r"^(.*?)\s*<[^<>]+>$", t)
        if label:                       # :ref:`the title <target>`
            return f"`{label.group(1)}`"
        if t.startswith("~"):           # :class:`~a.b.World` shows World
            t = t[1:].rsplit(".", 1)[-1]
        return f"`{t}`"

    text = _ROLE.sub(role, text)
    return re.sub(r"``([^`]+)``", r"`\1`", text)


def _summary(cls) -> str:
    """The docstring's first sentence (a full stop followed by a capital
    letter ends it; "eq. 1" does not)."""
    import re
    para = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
    return re.split(r"(?<=\.)\s+(?=[A-Z`(])", para, maxsplit=1)[0]


def _random(kind, **extra):
    return {kind: {"n": "$agents", "area": [50, 50], **extra, "seed": "$seed"}}


def template_of(cls) -> dict | None:
    """The arguments a block dragged onto a new diagram starts with: the
    class's ``example``, else one value per required argument derived from
    its declaration (``n``: ``$agents``; an (N, 3) pose: random poses; an
    (N, 2) or (N, 3) position: random positions; waypoints: random
    waypoints). None when a required argument cannot be derived."""
    if getattr(cls, "example", None) is not None:
        return json.loads(json.dumps(cls.example))
    t = {}
    for d in constructor_parameters(cls):
        if not d.required:
            continue
        if d.name == "n":
            t["n"] = "$agents"
        elif d.name == "waypoints":
            t[d.name] = {"random_waypoints": {"n": "$agents", "count": 3,
                                              "area": [50, 50], "seed": "$seed"}}
        elif d.kind == "per_agent" and "pose" in d.name and d.shape == "(N, 3)":
            t[d.name] = _random("random_poses")
        elif d.kind == "per_agent" and d.shape in ("(N, 2)", "(N, 3)", "(N, dim)"):
            t[d.name] = _random("random_positions",
                                **({"dim": 3} if d.shape == "(N, 3)" else {}))
        else:
            return None
    return t


def build_template(cls, typ, template, agents=TEMPLATE_AGENTS, seed=1):
    """An instance of ``cls`` built from ``template`` with ``$agents`` =
    ``agents`` (resolved as a scenario file's block arguments are)."""
    from ..scenarios.loader import Scenario
    sc = Scenario({"name": "palette", "parameters": {"agents": agents, "seed": seed},
                   "blocks": {"b": {"type": typ}}}, "<palette>")
    kwargs = sc.value(dict(template), f"blocks.{typ}")
    return cls(**kwargs)


def describe(cls, typ) -> dict:
    """One block's palette entry (see API.md)."""
    params = constructor_parameters(cls)
    template = template_of(cls)
    entry = {"type": typ, "name": cls.__name__, "summary": plain(_summary(cls)),
             "doc": inspect.cleandoc(cls.__doc__ or ""), "inputs": [], "outputs": [],
             "params": [], "template": template, "ports_depend_on": [], "error": None}
    block = None
    if template is None:
        entry["error"] = "no template: give the class an `example`"
    else:
        try:
            block = build_template(cls, typ, template)
        except ImportError as e:                # an extra is missing here
            entry["error"] = f"needs an optional extra that is not installed: {e}"
        except (AvError, TypeError, ValueError) as e:
            entry["error"] = f"the template does not build: {e}"
    if block is not None:
        # "N" only where the template follows $agents (an interface block's
        # vehicles are those of its scene: a number)
        entry.update(block.port_table(TEMPLATE_AGENTS,
                                      symbolic="$agents" in json.dumps(template)))
        n = getattr(block, "n", None)
        for d in params:
            spec = block.parameters.get(d.name)
            if spec is None:
                continue
            d.numeric = True
            lo, hi = spec.bounds
            d.bounds = [d.bounds[0] if d.bounds[0] is not None else lo,
                        d.bounds[1] if d.bounds[1] is not None else hi]
            d.unit = d.unit or spec.unit
            if not d.shape or d.kind in ("float", "any"):
                shape = tuple(spec.shape)
                d.shape = shape_text(shape, True, n) if shape else "()"
    entry["ports_depend_on"] = sorted(k for k, v in (template or {}).items()
                                      if "$agents" in json.dumps(v))
    entry["params"] = [_jsonable(d.to_dict()) for d in params]
    for row in [*entry["params"], *entry["inputs"], *entry["outputs"]]:
        row["doc"] = plain(row.get("doc"))
    return entry


def _generators() -> list:
    from ..scenarios.generators import GENERATORS
    out = []
    for name, fn in GENERATORS.items():
        args = []
        for a, p in inspect.signature(fn).parameters.items():
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                continue
            default = None if p.default is p.empty else p.default
            kind = ("int" if a in ("n", "count", "agents", "seed", "stream") else
                    type(default).__name__ if isinstance(default, (bool, int, float, str))
                    else "any")
            args.append({"name": a, "kind": kind, "required": p.default is p.empty,
                         "default": _jsonable(default)})
        doc = inspect.cleandoc(fn.__doc__ or "")
        ret = doc_sections(doc).get("Returns", {})
        out.append({"name": name, "doc": doc, "args": args,
                    "returns": next(iter(ret), None) if ret else None})
    return out


def palette(extra_modules=()) -> dict:
    """The palette JSON of API.md: ``{"families": [...], "generators":
    [...], "version": str}``; ``extra_modules``: module names whose blocks
    form a family each (``--blocks mypackage.blocks``)."""
    from .. import __version__
    from ..scenarios.loader import block_registry, module_blocks
    # interfaces: the physics and camera blocks a file may name (their
    # entries say what extra they need where it is missing)
    reg = block_registry(interfaces=True)
    families = []
    for fam in FAMILIES:
        blocks = [describe(cls, typ) for typ, cls in reg.items()
                  if typ.split(".", 1)[0] == fam]
        if blocks:
            families.append({"name": fam, "title": TITLES[fam], "blocks": blocks})
    for module in extra_modules or ():
        blocks = [describe(cls, typ) for typ, cls in module_blocks(module).items()]
        families.append({"name": module, "title": module, "blocks": blocks})
    return {"families": families, "generators": _generators(), "version": __version__,
            "parameters": dict(NEW_PARAMETERS)}
