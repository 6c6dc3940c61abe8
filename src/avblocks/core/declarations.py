"""What a block class declares about itself, read without a diagram: its
constructor parameters and its ports.

A block's ports are declared in ``__init__`` (their shapes depend on the
arguments), its numeric parameters by ``declare_parameter``; its other
constructor arguments only have a signature and a numpydoc ``Parameters``
section. :func:`constructor_parameters` joins those three sources, plus the
class's own ``parameter_info`` (for what neither says: bounds of a
non-numeric argument, choices, a kind), into one record per argument;
:func:`port_table` gives an instance's ports with the agent axis written
``N`` (``"(N, 3)"``). Tools that show blocks (the editor's palette, ``avblocks
list``) read these instead of special-casing blocks.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import asdict, dataclass, field

_SECTION = re.compile(r"^(\s*)([A-Z][A-Za-z ]+)\n\1-{3,}\s*$", re.M)
_SHAPE = re.compile(r"\(([^()]*)\)")
_UNIT = re.compile(r"\[([^\[\]]+)\]")
_INLINE = re.compile(r";\s+(?=[A-Za-z_][\w, ]*\s:\s)")
_CHOICES = re.compile(r"\{([^{}]+)\}")
KINDS = ("float", "int", "bool", "str", "choice", "array", "per_agent", "world",
         "footprint", "mapping", "list", "any")


@dataclass
class ParameterDecl:
    """One constructor argument of a block, as tools show it.

    Attributes
    ----------
    name : str
        The argument's name.
    kind : str
        One of :data:`KINDS` (``per_agent``: an array with the agent axis
        first, which a scenario file may give with a generator).
    shape : str
        ``"()"`` for a scalar, ``"(N, 3)"``-style text for arrays, ``""``
        when unknown.
    default : object
        The signature's default (plain values only; None otherwise).
    required : bool
        True when the signature has no default.
    bounds : list
        ``[low, high]`` (None: open).
    unit : str
        Units, free text.
    doc : str
        The docstring's description of the argument.
    choices : list or None
        The allowed values of a ``choice``.
    numeric : bool
        True for a numeric parameter (``declare_parameter``): changeable
        without a rebuild (``--set block.param=``).
    type_text : str
        The docstring's type text as written.
    """

    name: str
    kind: str = "any"
    shape: str = ""
    default: object = None
    required: bool = False
    bounds: list = field(default_factory=lambda: [None, None])
    unit: str = ""
    doc: str = ""
    choices: list | None = None
    numeric: bool = False
    type_text: str = ""

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("type_text")
        return d


def doc_sections(doc) -> dict:
    """``{section title: {name: (type text, description)}}`` of a numpydoc
    docstring's name-list sections (``Parameters``, ``Ports``, ...). A line
    ``a, b : float`` gives both names."""
    doc = inspect.cleandoc(doc or "")
    heads = list(_SECTION.finditer(doc))
    out = {}
    for i, m in enumerate(heads):
        body = doc[m.end():heads[i + 1].start() if i + 1 < len(heads) else len(doc)]
        entries, current = {}, None
        for line in body.splitlines():
            if not line.strip():
                continue
            if not line.startswith((" ", "\t")):
                # "a : int;  b : float > 0 -- text" declares several on one line
                for part in _INLINE.split(line):
                    names, sep, typ = part.partition(" : ")
                    if not sep and part.rstrip().endswith(":"):
                        names, typ = part.rstrip()[:-1], ""
                    current = [n.strip() for n in names.split(",") if n.strip()]
                    typ = re.split(r"\s+(?:\u2014|--)\s+", typ, maxsplit=1)[0]
                    for n in current:
                        entries[n] = [typ.strip().rstrip(";."), []]
            elif current:
                for n in current:
                    entries[n][1].append(line.strip())
        out[m.group(2).strip()] = {k: (t, " ".join(d)) for k, (t, d) in entries.items()}
    return out


def _plain_default(v):
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, (list, tuple)) and all(isinstance(x, (bool, int, float, str))
                                            for x in v):
        return list(v)
    return None


def _kind_from_type(typ: str, default) -> tuple[str, str, list | None]:
    """``(kind, shape text, choices)`` from a docstring type text."""
    t = typ.strip()
    low = t.lower()
    choices = None
    m = _CHOICES.search(t)
    if m and re.search(r"['\"]", m.group(1)):
        choices = [c.strip().strip("'\"") for c in m.group(1).split(",") if c.strip()]
        return "choice", "()", choices
    quoted = re.fullmatch(r"""\s*(["'][^"']*["'](\s*(,|\bor\b)\s*["'][^"']*["'])+)"""
                          r"(,\s*optional)?\s*", t)
    if quoted:
        return "choice", "()", re.findall(r"""["']([^"']*)["']""", quoted.group(1))
    shape = ""
    for s in _SHAPE.findall(t):
        parts = [p.strip() for p in s.split(",") if p.strip()]
        if parts and all(re.fullmatch(r"[A-Za-z_0-9]+", p) for p in parts):
            shape = "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"
            break
    first = re.split(r"\bor\b|,", low)[0].strip()
    if shape and shape.startswith("(N") and not first.startswith(("float", "int", "bool")):
        return "per_agent", shape, None
    if first.startswith("bool"):
        return "bool", "()", None
    if re.match(r"(int|whole)", first):
        return "int", "()", None
    if first.startswith(("float", "number", "scalar")):
        return "float", "()", None
    if first.startswith(("str", "text")):
        return "str", "()", None
    if "world" in first:
        return "world", "", None
    if "footprint" in first:
        return "footprint", "", None
    if first.startswith(("dict", "mapping")):
        return "mapping", "", None
    if first.startswith(("list", "sequence", "tuple")):
        return "list", shape, None
    if first.startswith(("array", "ndarray")) or shape:
        return ("per_agent" if shape.startswith("(N") else "array"), shape, None
    if first.startswith(("callable", "function")):
        return "any", "", None
    return _kind_from_default(default), ("()" if _kind_from_default(default) in
                                         ("float", "int", "bool", "str") else ""), None


def _kind_from_default(v) -> str:
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, int):
        return "int"
    if isinstance(v, float):
        return "float"
    if isinstance(v, str):
        return "str"
    return "any"


def constructor_parameters(cls) -> list[ParameterDecl]:
    """The constructor arguments of block class ``cls``: names, defaults
    and requiredness from the signature; kind, shape, choices, unit and
    description from the class docstring's ``Parameters`` section; then
    the class's ``parameter_info`` (``{name: {field: value}}``) on top."""
    try:
        sig = inspect.signature(cls.__init__)
    except (TypeError, ValueError):
        return []
    docs = doc_sections(cls.__doc__).get("Parameters", {})
    info = getattr(cls, "parameter_info", None) or {}
    out = []
    for name, p in sig.parameters.items():
        if name == "self" or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        default = None if p.default is p.empty else p.default
        typ, desc = docs.get(name, ("", ""))
        kind, shape, choices = _kind_from_type(typ, default)
        um = _UNIT.search(typ)
        decl = ParameterDecl(name, kind, shape, _plain_default(default),
                             p.default is p.empty, [None, None],
                             um.group(1) if um else "", desc, choices, False, typ)
        if name == "n":     # every block's n is its number of agents (core.block checks it)
            decl.kind, decl.shape, decl.bounds = "int", "()", [1, None]
        for k, v in (info.get(name) or {}).items():
            setattr(decl, k, list(v) if k == "bounds" else v)
        out.append(decl)
    return out


def shape_text(shape, agents=False, n=None) -> str:
    """``"(N, 3)"``-style text of a port shape: the leading axis written
    ``N`` when it is the agent axis (``agents``) and has ``n`` entries."""
    if shape is None:
        return "(any)"
    dims = [str(s) for s in shape]
    if agents and dims and n is not None and shape[0] == n:
        dims[0] = "N"
    return "(" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"


def port_table(block, n=None, *, symbolic=True) -> dict:
    """``{"inputs": [...], "outputs": [...]}`` of a block instance: each
    port's name, shape text with the agent axis as ``N`` (the block's
    ``n``, else the ``n`` given; ``symbolic=False``: numbers only, for a
    block whose size is fixed rather than the diagram's agent count),
    dtype, unit and description (the port's own, else the docstring's
    ``Ports`` section)."""
    n = getattr(block, "n", n) if symbolic else None
    try:
        n = int(n) if n is not None else None
    except (TypeError, ValueError):
        n = None
    docs = doc_sections(type(block).__doc__).get("Ports", {})

    def row(p):
        typ, desc = docs.get(p.name, ("", ""))
        um = _UNIT.search(typ)
        return {"name": p.name, "shape": shape_text(p.shape, p.agents, n),
                "dtype": str(p.dtype), "unit": p.unit or (um.group(1) if um else ""),
                "doc": p.doc or desc}

    return {"inputs": [row(p) for p in block._inputs.values()],
            "outputs": [row(p) for p in block._outputs.values()]}
