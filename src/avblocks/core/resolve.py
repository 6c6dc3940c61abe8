"""Resolving a flattened diagram: port shapes, inherited sample times, evaluation order.

The three passes :class:`~avblocks.core.diagram.CompiledDiagram` makes over
the leaf blocks and their wires (``srcs[i] = {input: (block, output)}``):
shapes propagate along wires until every port is known (``configure`` lets a
block fix its outputs from its inputs), a block declared
:class:`~avblocks.core.sample_times.Inherited` takes its drivers' sample time, and a
depth-first sort over direct-feedthrough wires gives the evaluation order (a
cycle without a state on it is an :class:`AlgebraicLoopError`).
"""

from __future__ import annotations

from .block import CONTINUOUS, Inherited, Periodic
from .errors import AlgebraicLoopError, ShapeError
from .ports import Port, check_compatible


def _inputs_of(b) -> dict[str, Port]:
    return b.input_ports


def _outputs_of(b) -> dict[str, Port]:
    return b.output_ports


def _resolve_shapes(names, blocks, srcs):
    """Give every port a concrete shape, calling ``configure`` on each block
    once the specs of all signals wired to it are known."""
    configured = [False] * len(blocks)
    progress = True
    while progress and not all(configured):
        progress = False
        for i, b in enumerate(blocks):
            if configured[i]:
                continue
            specs = {}
            ready = True
            for inp, (s, o) in srcs[i].items():
                sp = _outputs_of(blocks[s])[o]
                if sp.shape is None:
                    ready = False
                    break
                specs[inp] = sp
            if not ready:
                continue
            for inp, sp in specs.items():
                mine = _inputs_of(b)[inp]
                if mine.shape is None or inp in getattr(b, "_inherited", ()):
                    b.redeclare_input(inp, sp.shape, sp.dtype)
            try:
                b.configure(specs)
            except ShapeError as e:
                if e.block is None or e.block == type(b).__name__:
                    e.block = names[i]
                    e.args = (e._format(),)
                raise
            except Exception as e:  # noqa: BLE001 - add context, keep cause
                raise ShapeError(f"configure failed: {e}", block=names[i]) from e
            for o, p in _outputs_of(b).items():
                if p.shape is None:
                    raise ShapeError("output shape still unknown after configure()",
                                     block=names[i], port=o)
            configured[i] = True
            progress = True
    if not all(configured):
        todo = [names[i] for i in range(len(blocks)) if not configured[i]]
        raise ShapeError("cannot infer port shapes: these blocks only take their "
                         "shapes from each other", found=todo,
                         hint="give one block on the cycle an explicit shape "
                              "(e.g. an initial value)")
    for i, b in enumerate(blocks):
        for inp, (s, o) in srcs[i].items():
            check_compatible(_outputs_of(blocks[s])[o], _inputs_of(b)[inp],
                             src_name=f"{names[s]}.{o}", dst_name=f"{names[i]}.{inp}")


def _resolve_sample_times(blocks, srcs, order):
    """Give each block declared :class:`Inherited` its drivers' sample time,
    in evaluation order (so chains of inherited blocks resolve too). A block
    remembers it was inherited, so a later build resolves it afresh."""
    for b in blocks:
        if isinstance(b.sample_time, Inherited) or getattr(b, "_inherits", False):
            b._inherits = True
            b.sample_time = Inherited()
    for i in order:
        b = blocks[i]
        if not getattr(b, "_inherits", False):
            continue
        times = {blocks[s].sample_time for (s, _o) in srcs[i].values()}
        if len(times) == 1 and isinstance(next(iter(times)), Periodic) and not b._cstates:
            b.sample_time = next(iter(times))
        else:
            b.sample_time = CONTINUOUS


def _sort(names, blocks, srcs) -> list[int]:
    """Topological order over direct-feedthrough wires; loops are errors."""
    n = len(blocks)
    deps = [set() for _ in range(n)]
    for i, b in enumerate(blocks):
        ft = b.feedthrough
        for inp, (s, _o) in srcs[i].items():
            if inp in ft:
                deps[i].add(s)
    order, state = [], [0] * n   # 0 new, 1 visiting, 2 done

    def visit(i, stack):
        if state[i] == 2:
            return
        if state[i] == 1:
            k = stack.index(i)
            cyc = stack[k:] + [i]
            wires = []
            for a, b2 in zip(cyc[:-1], cyc[1:]):
                port, out = next((inp, o) for inp, (s, o) in srcs[a].items()
                                 if s == b2 and inp in blocks[a].feedthrough)
                wires.append(f"{names[b2]}.{out} -> {names[a]}.{port}")
            raise AlgebraicLoopError(list(reversed(wires)))
        state[i] = 1
        stack.append(i)
        for s in sorted(deps[i]):
            visit(s, stack)
        stack.pop()
        state[i] = 2
        order.append(i)

    for i in range(n):
        visit(i, [])
    return order

