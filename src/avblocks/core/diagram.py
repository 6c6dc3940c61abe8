"""Diagrams: blocks wired together, usable themselves as blocks (subsystems).

>>> import avblocks as av
>>> d = av.Diagram()
>>> src = d.add(av.blocks.Constant([[1.0, 2.0]]), name="src")
>>> k = d.add(av.blocks.Gain(3.0), name="k")
>>> d.connect(src.y, k.u)
>>> d.build().order
['src', 'k']

Wiring uses port handles (``handle.port_name``); every mistake is reported
when it is made or, at the latest, when the diagram is built: unknown ports,
an input driven twice, an input left unconnected, shape, dtype and
agent-count mismatches, and algebraic loops (with the cycle printed).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

from .block import Block
from .errors import ParameterError, WiringError
from .ports import Port, check_compatible
from .resolve import (
    _inputs_of,
    _outputs_of,
    _resolve_sample_times,
    _resolve_shapes,
    _sort,
)


class PortRef:
    """A handle to one port of one block in a diagram (``fleet.pose``)."""

    __slots__ = ("handle", "name")

    def __init__(self, handle: BlockHandle, name: str):
        self.handle = handle
        self.name = name

    @property
    def path(self) -> str:
        return f"{self.handle.path}.{self.name}"

    def __repr__(self):
        return f"<port {self.path}>"

    def __eq__(self, other):
        return (isinstance(other, PortRef) and other.handle is self.handle
                and other.name == self.name)

    def __hash__(self):
        return hash((id(self.handle), self.name))


class BlockHandle:
    """What :meth:`Diagram.add` returns: the block plus its name in the
    diagram. Its attributes are its ports: ``handle.pose`` is a
    :class:`PortRef`."""

    def __init__(self, diagram: Diagram, name: str, block):
        object.__setattr__(self, "diagram", diagram)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "block", block)

    @property
    def path(self) -> str:
        prefix = self.diagram._path_prefix()
        return prefix + self.name

    def _ports(self):
        return set(_inputs_of(self.block)) | set(_outputs_of(self.block))

    def __getattr__(self, name) -> PortRef:
        if name.startswith("__") and name.endswith("__"):
            # Python's protocols (copy, pickle, IPython) probe dunders with
            # getattr(obj, name, default): they expect a plain AttributeError
            raise AttributeError(f"'{type(self).__name__}' object has no attribute "
                                 f"{name!r}")
        return self.port(name)

    def port(self, name) -> PortRef:
        """The port called ``name`` (for names that are not identifiers);
        a :class:`WiringError` naming the block's ports when there is none
        (dunder names included: a wire ``fleet.__class__`` is an unknown port)."""
        if isinstance(name, str) and name in self._ports():
            return PortRef(self, name)
        from .errors import did_you_mean
        shown = name if isinstance(name, str) else repr(name)[:60]
        raise WiringError(
            "unknown port", block=self.name, port=shown,
            expected=f"one of inputs {sorted(_inputs_of(self.block))} or "
                     f"outputs {sorted(_outputs_of(self.block))}", found=shown,
            hint=did_you_mean(shown, self._ports()).strip() or None)

    def __setattr__(self, name, value):
        raise AttributeError("block handles are read-only")

    def __repr__(self):
        return f"<{type(self.block).__name__} '{self.path}'>"


#: block -> weak reference to the diagram holding it (one diagram per block)
_OWNER = weakref.WeakKeyDictionary()


class Diagram:
    """A set of named blocks and the wires between their ports.

    A diagram can be added to another diagram as a block (a subsystem):
    :meth:`export_input` and :meth:`export_output` give it ports.
    """

    def __init__(self, name: str | None = None):
        self.name = name
        self._handles: dict[str, BlockHandle] = {}
        self._driver: dict[PortRef, PortRef] = {}     # dst -> src
        self._ex_in: dict[str, list[PortRef]] = {}
        self._ex_out: dict[str, PortRef] = {}
        self._parent_handle: BlockHandle | None = None
        self._stamp = 0           # wiring changes of this diagram and its subsystems

    def _touch(self):
        """Count a wiring change here and in every diagram holding this one
        (an engine that keeps a run of this diagram compares the count)."""
        d = self
        while d is not None:
            d._stamp += 1
            h = d._parent_handle
            d = h.diagram if h is not None else None

    # --------------------------------------------------------------- building
    def _path_prefix(self) -> str:
        h = self._parent_handle
        return (h.path + ".") if h is not None else ""

    def add(self, block, name: str | None = None) -> BlockHandle:
        """Add ``block`` (a :class:`Block` or a :class:`Diagram`) under ``name``."""
        if not isinstance(block, (Block, Diagram)):
            raise WiringError("only Blocks and Diagrams can be added",
                              expected="Block or Diagram", found=type(block).__name__)
        if isinstance(block, Block) and not hasattr(block, "_inputs"):
            raise ParameterError(f"{type(block).__name__}.__init__ did not call "
                                 "super().__init__()")
        if name is None:
            base = type(block).__name__.lower()
            i = 0
            while f"{base}{i}" in self._handles:
                i += 1
            name = f"{base}{i}"
        if not name.isidentifier():
            raise WiringError("block name must be an identifier",
                              expected="e.g. 'fleet'", found=repr(name))
        if name in self._handles:
            raise WiringError("a block of that name exists already", block=name)
        ref = _OWNER.get(block) if isinstance(block, Block) else None
        other = ref() if ref is not None else None
        if other is self or isinstance(block, Diagram):   # (a block: no scan of all)
            for h in self._handles.values():
                if h.block is block:
                    raise WiringError(f"this block object is already in the diagram as "
                                      f"'{h.name}'", block=name,
                                      hint="create a second block instance")
        if isinstance(block, Block):
            if other is not None and other is not self:
                raise WiringError("this block object is already in another diagram",
                                  block=name,
                                  hint="a block belongs to one diagram: create a second "
                                       "instance (or copy.deepcopy the block)")
            _OWNER[block] = weakref.ref(self)
        h = BlockHandle(self, name, block)
        if isinstance(block, Diagram):
            if block._parent_handle is not None:
                raise WiringError("this subsystem is already part of another "
                                  "diagram", block=name)
            block._parent_handle = h
        self._handles[name] = h
        self._touch()
        return h

    def __getitem__(self, name) -> BlockHandle:
        return self._handles[name]

    @property
    def blocks(self) -> dict[str, BlockHandle]:
        return dict(self._handles)

    def _own(self, ref, what):
        if not isinstance(ref, PortRef):
            raise WiringError(f"{what} must be a port handle such as fleet.pose",
                              expected="PortRef", found=type(ref).__name__)
        if ref.handle.diagram is not self:
            raise WiringError(f"{what} {ref.path} belongs to another diagram",
                              hint="wire blocks inside the diagram that holds "
                                   "them; export ports from subsystems")

    def connect(self, src: PortRef, dst: PortRef) -> None:
        """Wire output ``src`` to input ``dst``."""
        self._own(src, "source")
        self._own(dst, "destination")
        outs = _outputs_of(src.handle.block)
        ins = _inputs_of(dst.handle.block)
        if src.name not in outs:
            raise WiringError("not an output port", block=src.handle.name,
                              port=src.name, expected=f"one of {sorted(outs)}",
                              found=src.name)
        if dst.name not in ins:
            raise WiringError("not an input port", block=dst.handle.name,
                              port=dst.name, expected=f"one of {sorted(ins)}",
                              found=dst.name)
        if dst in self._driver:
            raise WiringError(
                f"input is already driven by {self._driver[dst].path}",
                block=dst.handle.name, port=dst.name,
                hint="an input has exactly one driver; use a Sum or Mux block "
                     "to combine signals")
        check_compatible(outs[src.name], ins[dst.name], src_name=src.path,
                         dst_name=dst.path)
        self._driver[dst] = src

    def export_input(self, name: str, *dsts: PortRef) -> None:
        """Make ``name`` an input of this diagram that drives ``dsts``."""
        for d in dsts:
            self._own(d, "destination")
            if d.name not in _inputs_of(d.handle.block):
                raise WiringError("not an input port", block=d.handle.name,
                                  port=d.name)
            if d in self._driver:
                raise WiringError("input is already driven", block=d.handle.name,
                                  port=d.name)
        if name in self._ex_in or name in self._ex_out:
            raise WiringError("port exported twice", block=self.name, port=name)
        self._ex_in[name] = list(dsts)
        self._touch()

    def export_output(self, name: str, src: PortRef) -> None:
        """Make ``name`` an output of this diagram, driven by ``src``."""
        self._own(src, "source")
        if src.name not in _outputs_of(src.handle.block):
            raise WiringError("not an output port", block=src.handle.name,
                              port=src.name)
        if name in self._ex_in or name in self._ex_out:
            raise WiringError("port exported twice", block=self.name, port=name)
        self._ex_out[name] = src
        self._touch()

    # Diagram as a block: the specs of its exported ports.
    @property
    def input_ports(self) -> dict[str, Port]:
        res = {}
        for name, dsts in self._ex_in.items():
            p = _inputs_of(dsts[0].handle.block)[dsts[0].name] if dsts else Port(name)
            res[name] = Port(name, p.shape, p.dtype, p.unit, p.labels, p.doc, p.agents)
        return res

    @property
    def output_ports(self) -> dict[str, Port]:
        res = {}
        for name, src in self._ex_out.items():
            p = _outputs_of(src.handle.block)[src.name]
            res[name] = Port(name, p.shape, p.dtype, p.unit, p.labels, p.doc, p.agents)
        return res

    def build(self) -> CompiledDiagram:
        """Flatten, resolve shapes, check every input is driven, sort."""
        return CompiledDiagram(self)

    def unconnected_inputs(self) -> list[str]:
        """Every input of a leaf block that no wire drives, as ``"block.port"``
        paths (dotted through subsystems), in the order blocks were added.
        :meth:`build` stops at the first of them; this lists them all (the
        editor marks each one)."""
        leaves, wires = _flatten(self, "")
        driven = {dst for _src, dst in wires}
        return [f"{name}.{inp}" for name, b in leaves for inp in _inputs_of(b)
                if (name, inp) not in driven]

    # ------------------------------------------------------------- pictures
    def to_graphviz(self) -> str:
        """The diagram in Graphviz DOT text (blocks, ports, wires)."""
        from .plotting import get_backend
        return get_backend().to_dot(self)

    def __repr__(self):
        kinds = ", ".join(f"{n}: {type(h.block).__name__}" for n, h in self._handles.items())
        name = f" {self.name!r}" if self.name else ""
        return (f"<Diagram{name}: {len(self._handles)} blocks, {len(self._driver)} wires"
                f"{' (' + kinds + ')' if kinds and len(kinds) < 200 else ''}>")

    def _repr_svg_(self):
        """The diagram as an SVG picture, for Jupyter (drawn by the plotting
        backend, :func:`avblocks.viz.draw_diagram`'s Matplotlib layout).
        ``None`` (Jupyter then shows the text repr) while the diagram cannot
        be drawn yet, e.g. before its inputs are wired."""
        from .errors import AvError
        from .plotting import get_backend
        if not self._handles:
            return None
        try:
            return get_backend().diagram_svg(self)
        except AvError:
            return None


@dataclass
class CompiledDiagram:
    """A flat, checked, sorted view of a diagram, ready to simulate.

    Attributes
    ----------
    names : list of str
        Dotted paths of the leaf blocks, in evaluation order.
    blocks : list of Block
    sources : list of dict
        For each block, ``{input_name: (block_index, output_name)}``.
    """

    diagram: Diagram
    names: list = field(default_factory=list)
    blocks: list = field(default_factory=list)
    sources: list = field(default_factory=list)

    def __post_init__(self):
        leaves, wires = _flatten(self.diagram, "")
        names = [p for p, _ in leaves]
        blocks = [b for _, b in leaves]
        index = {p: i for i, p in enumerate(names)}
        srcs: list[dict] = [{} for _ in blocks]
        for (sp, so), (dp, di) in wires:
            srcs[index[dp]][di] = (index[sp], so)
        # every input driven
        for i, b in enumerate(blocks):
            for inp in _inputs_of(b):
                if inp not in srcs[i]:
                    raise WiringError("input is not connected", block=names[i],
                                      port=inp,
                                      hint="connect it with diagram.connect(src, "
                                           f"{names[i].rsplit('.', 1)[-1]}.{inp})")
        order = _sort(names, blocks, srcs)
        _resolve_shapes(names, blocks, srcs)
        _resolve_sample_times(blocks, srcs, order)
        remap = {old: new for new, old in enumerate(order)}
        self.names = [names[i] for i in order]
        self.blocks = [blocks[i] for i in order]
        self.sources = [{k: (remap[s], o) for k, (s, o) in srcs[i].items()}
                        for i in order]
        self._index = {n: i for i, n in enumerate(self.names)}

    @property
    def order(self) -> list[str]:
        return list(self.names)

    def index(self, path: str) -> int:
        try:
            return self._index[path]
        except KeyError:
            raise WiringError("no such block", expected=f"one of {self.names}",
                              found=path) from None

    def resolve(self, ref) -> tuple[int, str]:
        """(block index, output name) of a port handle or ``"a.b.port"`` path,
        following subsystem exports to the leaf block that drives it."""
        if isinstance(ref, PortRef):
            blk = ref.handle.block
            if isinstance(blk, Diagram):
                if ref.name not in blk._ex_out:
                    raise WiringError("not an exported output", block=ref.handle.path,
                                      port=ref.name)
                return self.resolve(blk._ex_out[ref.name])
            path, name = ref.handle.path, ref.name
        else:
            path, _, name = str(ref).rpartition(".")
            if path in self._index:
                pass
            else:
                # a subsystem path: find its handle
                h = _find_handle(self.diagram, path)
                if h is None:
                    raise WiringError("no such block", expected=f"one of {self.names}",
                                      found=path)
                return self.resolve(PortRef(h, name))
        i = self.index(path)
        if name not in _outputs_of(self.blocks[i]):
            raise WiringError("not an output port", block=path, port=name,
                              expected=f"one of {sorted(_outputs_of(self.blocks[i]))}",
                              found=name)
        return i, name


    # ------------------------------------------------- numeric parameters
    def parameters(self) -> dict:
        """Every numeric parameter of the diagram: ``{"block.path.name": Param}``
        in evaluation order of the blocks."""
        return {f"{n}.{k}": spec for n, b in zip(self.names, self.blocks)
                for k, spec in b._params.items()}

    def param_index(self, path) -> tuple[int, str]:
        """(block index, parameter name) of ``"block.path.name"``."""
        bpath, _, name = str(path).rpartition(".")
        if not bpath or bpath not in self._index:
            import difflib
            close = difflib.get_close_matches(str(path), list(self.parameters()), n=3)
            raise ParameterError(
                "no such numeric parameter", param=str(path),
                expected="'<block path>.<parameter>'",
                found=str(path),
                hint=(f"did you mean {close}?" if close else
                      f"the diagram's parameters: {sorted(self.parameters())[:20]}"))
        i = self._index[bpath]
        self.blocks[i]._param_spec(name, bpath)
        return i, name

    def get_param(self, path):
        """Current value of ``"block.name"`` (a copy)."""
        i, name = self.param_index(path)
        return self.blocks[i].get_parameter(name)

    def set_param(self, path, value):
        """Validate and set ``"block.name"`` on its block."""
        i, name = self.param_index(path)
        self.blocks[i].set_parameter(name, value, block=self.names[i])

    def param_values(self) -> dict:
        """``{"block.name": value}`` of every numeric parameter (no copies)."""
        return {f"{n}.{k}": v for n, b in zip(self.names, self.blocks)
                for k, v in b.parameter_values().items()}


def _find_handle(d: Diagram, path: str):
    parts = path.split(".")
    cur = d
    h = None
    for p in parts:
        if not isinstance(cur, Diagram) or p not in cur._handles:
            return None
        h = cur._handles[p]
        cur = h.block
    return h


def flatten(diagram: Diagram):
    """The leaf blocks and wires of ``diagram`` with subsystems opened:
    ``([(path, block)], [((src_path, output), (dst_path, input))])``, paths
    dotted from the top (``"team.fleet"``), in the order blocks were added."""
    return _flatten(diagram, "")


def _flatten(d: Diagram, prefix: str):
    """Leaves ``[(path, block)]`` and wires ``[((src_path, out), (dst_path, in))]``."""
    leaves, wires = [], []
    for name, h in d._handles.items():
        if isinstance(h.block, Diagram):
            sub_leaves, sub_wires = _flatten(h.block, prefix + name + ".")
            leaves += sub_leaves
            wires += sub_wires
        else:
            leaves.append((prefix + name, h.block))
    for dst, src in d._driver.items():
        for s in _leaf_sources(src, prefix):
            for t in _leaf_dests(dst, prefix):
                wires.append((s, t))
    return leaves, wires


def _leaf_sources(ref: PortRef, prefix: str):
    blk = ref.handle.block
    if isinstance(blk, Diagram):
        if ref.name not in blk._ex_out:
            raise WiringError("subsystem output is not exported", block=ref.handle.path,
                              port=ref.name)
        return _leaf_sources(blk._ex_out[ref.name], prefix + ref.handle.name + ".")
    return [(prefix + ref.handle.name, ref.name)]


def _leaf_dests(ref: PortRef, prefix: str):
    blk = ref.handle.block
    if isinstance(blk, Diagram):
        out = []
        for d in blk._ex_in.get(ref.name, []):
            out += _leaf_dests(d, prefix + ref.handle.name + ".")
        return out
    return [(prefix + ref.handle.name, ref.name)]
