"""Pictures of diagrams: Graphviz DOT text (:func:`to_dot`) and image files
(:func:`draw_diagram`).

Blocks are boxes with their input ports on the left and output ports on
the right; wires go port to port, labelled with the signal shape;
subsystems are clusters. :func:`draw_diagram` runs Graphviz ``dot`` when it
is installed, otherwise draws a layered layout with Matplotlib.

>>> import numpy as np, avblocks as av, avblocks.viz
>>> d = av.Diagram()
>>> c = d.add(av.blocks.Constant(np.ones((2, 2))), name="c")
>>> k = d.add(av.blocks.Gain(2.0), name="k")
>>> d.connect(c.y, k.u)
>>> '"c":"o_y":e -> "k":"i_u":w' in av.viz.to_dot(d)
True
"""

from __future__ import annotations

import html
import shutil
import subprocess
from pathlib import Path

import numpy as np

from ..core.diagram import Diagram, flatten
from ..core.errors import ParameterError


def _q(s) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _shape_text(port) -> str:
    if port is None or port.shape is None:
        return "?"
    s = "(" + ", ".join(str(v) for v in port.shape) + ")"
    return s if port.dtype == "float64" else f"{s} {port.dtype}"


def _ports_in(b):
    return b.input_ports


def _ports_out(b):
    return b.output_ports


def _block_label(name, block) -> str:
    ins, outs = list(_ports_in(block)), list(_ports_out(block))
    rows = max(len(ins), len(outs), 1)
    e = html.escape
    title = (f'<B>{e(name)}</B><BR/><FONT POINT-SIZE="8" COLOR="#555555">'
             f"{e(type(block).__name__)}</FONT>")
    cells = []
    for r in range(rows):
        row = ""
        if ins:
            row += (f'<TD PORT="i_{e(ins[r])}" ALIGN="LEFT">{e(ins[r])}</TD>' if r < len(ins)
                    else '<TD BORDER="0"></TD>')
        if r == 0:
            row += f'<TD ROWSPAN="{rows}" BGCOLOR="#e8eef7" CELLPADDING="6">{title}</TD>'
        if outs:
            row += (f'<TD PORT="o_{e(outs[r])}" ALIGN="RIGHT">{e(outs[r])}</TD>'
                    if r < len(outs) else '<TD BORDER="0"></TD>')
        cells.append(f"<TR>{row}</TR>")
    return ('<<TABLE BORDER="1" CELLBORDER="1" CELLSPACING="0" CELLPADDING="3" '
            'STYLE="ROUNDED">' + "".join(cells) + "</TABLE>>")


def _ex_in_node(path, name):
    return f"{path}.@in.{name}"


def _ex_out_node(path, name):
    return f"{path}.@out.{name}"


def _src_end(ref, prefix):
    path = prefix + ref.handle.name
    if isinstance(ref.handle.block, Diagram):
        return _q(_ex_out_node(path, ref.name))
    return f'{_q(path)}:{_q("o_" + ref.name)}:e'


def _dst_end(ref, prefix):
    path = prefix + ref.handle.name
    if isinstance(ref.handle.block, Diagram):
        return _q(_ex_in_node(path, ref.name))
    return f'{_q(path)}:{_q("i_" + ref.name)}:w'


def _emit(d: Diagram, prefix: str, lines: list, edges: list, indent: str):
    for name, h in d._handles.items():
        path = prefix + name
        b = h.block
        if isinstance(b, Diagram):
            lines.append(f"{indent}subgraph {_q('cluster_' + path)} {{")
            lines.append(f'{indent}  label={_q(path)}; style="rounded,dashed"; '
                         f'color="#7a8699"; fontname="Helvetica";')
            for nm in b._ex_in:
                lines.append(f"{indent}  {_q(_ex_in_node(path, nm))} [shape=cds, "
                             f'label={_q(nm)}, style=filled, fillcolor="#f4f4f4"];')
            for nm in b._ex_out:
                lines.append(f"{indent}  {_q(_ex_out_node(path, nm))} [shape=cds, "
                             f'label={_q(nm)}, style=filled, fillcolor="#f4f4f4"];')
            _emit(b, path + ".", lines, edges, indent + "  ")
            for nm, dsts in b._ex_in.items():
                p = b.input_ports.get(nm)
                for dst in dsts:
                    edges.append(f"{_q(_ex_in_node(path, nm))} -> {_dst_end(dst, path + '.')}"
                                 f" [label={_q(_shape_text(p))}];")
            for nm, src in b._ex_out.items():
                p = _ports_out(src.handle.block).get(src.name)
                edges.append(f"{_src_end(src, path + '.')} -> {_q(_ex_out_node(path, nm))}"
                             f" [label={_q(_shape_text(p))}];")
            lines.append(f"{indent}}}")
        else:
            lines.append(f"{indent}{_q(path)} [label={_block_label(name, b)}];")
    for dst, src in d._driver.items():
        p = _ports_out(src.handle.block).get(src.name)
        edges.append(f"{_src_end(src, prefix)} -> {_dst_end(dst, prefix)} "
                     f"[label={_q(_shape_text(p))}];")


def _resolve_shapes(diagram):
    """Resolve inherited port shapes when the diagram builds (else keep '?')."""
    try:
        diagram.build()
    except Exception:  # noqa: BLE001 - an unfinished diagram still gets a picture
        pass


def to_dot(diagram: Diagram) -> str:
    """The diagram as Graphviz DOT text.

    Each leaf block is a node with an HTML-like table label: input ports
    (``PORT="i_<name>"``) left, the block name and type in the middle,
    output ports (``PORT="o_<name>"``) right. Wires go from ``"src":"o_y":e``
    to ``"dst":"i_u":w`` with the source port's shape as label. Subsystems
    are ``cluster_<path>`` subgraphs whose exported ports are small nodes.
    """
    if not isinstance(diagram, Diagram):
        raise ParameterError("to_dot needs a Diagram", param="diagram",
                             expected="Diagram", found=type(diagram).__name__)
    _resolve_shapes(diagram)
    lines = ["digraph avblocks {",
             '  rankdir=LR; nodesep=0.35; ranksep=0.7; splines=spline;',
             '  node [shape=plaintext, fontname="Helvetica", fontsize=10];',
             '  edge [fontname="Helvetica", fontsize=8, color="#33475b", '
             'fontcolor="#33475b", arrowsize=0.7];']
    if diagram.name:
        lines.append(f"  label={_q(diagram.name)}; labelloc=t;")
    edges: list[str] = []
    root = ""
    for nm in diagram._ex_in:
        lines.append(f"  {_q(_ex_in_node(root, nm))} [shape=cds, label={_q(nm)}];")
    for nm in diagram._ex_out:
        lines.append(f"  {_q(_ex_out_node(root, nm))} [shape=cds, label={_q(nm)}];")
    _emit(diagram, "", lines, edges, "  ")
    for nm, dsts in diagram._ex_in.items():
        for dst in dsts:
            edges.append(f"{_q(_ex_in_node(root, nm))} -> {_dst_end(dst, '')};")
    for nm, src in diagram._ex_out.items():
        edges.append(f"{_src_end(src, '')} -> {_q(_ex_out_node(root, nm))};")
    lines += ["  " + e for e in edges]
    lines.append("}")
    return "\n".join(lines) + "\n"


def draw_diagram(diagram: Diagram, path, *, engine=None, dpi=110):
    """Write a picture of ``diagram`` to ``path`` (``.svg``, ``.png``, ``.pdf``).

    ``engine``: ``"dot"`` (Graphviz, needs the ``dot`` program),
    ``"matplotlib"`` (built-in layered layout), or None: ``dot`` when it is
    installed, else Matplotlib. Returns the path.
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "svg"
    if fmt not in ("svg", "png", "pdf"):
        raise ParameterError("unknown picture format", param="path",
                             expected=[".svg", ".png", ".pdf"], found=path.suffix)
    if engine is None:
        engine = "dot" if shutil.which("dot") else "matplotlib"
    path.parent.mkdir(parents=True, exist_ok=True)
    if engine == "dot":
        exe = shutil.which("dot")
        if exe is None:
            raise ParameterError("Graphviz 'dot' is not installed", param="engine",
                                 hint="install graphviz, or use engine='matplotlib'")
        subprocess.run([exe, f"-T{fmt}", "-o", str(path)], input=to_dot(diagram),
                       text=True, check=True, capture_output=True)
        return path
    if engine != "matplotlib":
        raise ParameterError("unknown engine", param="engine",
                             expected=["dot", "matplotlib", None], found=engine)
    import matplotlib as mpl
    fig = draw_diagram_matplotlib(diagram)
    with mpl.rc_context({"svg.fonttype": "none"}):
        fig.savefig(path, dpi=dpi)
    return path


# ------------------------------------------------------ matplotlib fallback
def _layout(names, blocks, wires):
    """Layer (x) and order (y) of leaf blocks: longest path over the wires
    once each cycle is broken at a non-feedthrough input."""
    import networkx as nx
    g = nx.MultiDiGraph()
    g.add_nodes_from(names)
    bidx = dict(zip(names, blocks))
    for (sp, _so), (dp, di) in wires:
        g.add_edge(sp, dp, ft=di in bidx[dp].feedthrough)
    dag = nx.DiGraph()
    dag.add_nodes_from(names)
    for u, v, data in g.edges(data=True):
        if u == v:
            continue
        if not data["ft"] and (nx.has_path(dag, v, u) or nx.has_path(g, v, u)):
            continue                          # a feedback wire: drawn backwards
        if not nx.has_path(dag, v, u):
            dag.add_edge(u, v)
    layer = {}
    for nd in nx.topological_sort(dag):
        layer[nd] = max((layer[p] + 1 for p in dag.predecessors(nd)), default=0)
    cols: dict[int, list] = {}
    for nd in names:
        cols.setdefault(layer[nd], []).append(nd)
    order = {}
    for L in sorted(cols):
        def bary(nd):
            ps = [order[p] for p in g.predecessors(nd) if p in order]
            return np.mean(ps) if ps else names.index(nd) * 1e-3
        for i, nd in enumerate(sorted(cols[L], key=bary)):
            order[nd] = i
    return layer, order


def diagram_svg(diagram: Diagram) -> str:
    """The diagram as SVG text (the Matplotlib layout of
    :func:`draw_diagram`): what ``Diagram._repr_svg_`` shows in Jupyter."""
    import io
    fig = draw_diagram_matplotlib(diagram)
    buf = io.StringIO()
    fig.savefig(buf, format="svg")
    return buf.getvalue()


def draw_diagram_matplotlib(diagram: Diagram):
    """Matplotlib picture of a diagram (leaf blocks, ports, wires, subsystem
    frames); returns the Figure. SVG output keeps names as text and gives
    each wire the id ``wire <src>.<out> -> <dst>.<in>``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch, Rectangle

    _resolve_shapes(diagram)
    leaves, wires = flatten(diagram)
    names = [p for p, _ in leaves]
    blocks = [b for _, b in leaves]
    if not names:
        raise ParameterError("the diagram has no blocks", param="diagram")
    layer, order = _layout(names, blocks, wires)
    W, DX, PH, GAP = 2.4, 3.8, 0.38, 0.7
    geo = {}
    col_y: dict[int, float] = {}
    for nd in sorted(names, key=lambda n: (layer[n], order[n])):
        b = blocks[names.index(nd)]
        ins, outs = list(_ports_in(b)), list(_ports_out(b))
        h = 0.75 + PH * max(len(ins), len(outs), 1)
        y0 = col_y.get(layer[nd], 0.0)
        geo[nd] = dict(x=layer[nd] * DX, y=-y0 - h, h=h, ins=ins, outs=outs, b=b)
        col_y[layer[nd]] = y0 + h + GAP
    height = max(col_y.values())
    for nd, gm in geo.items():                 # centre each column vertically
        gm["y"] -= (height - col_y[layer[nd]]) / 2 - 0.0
    xs = [g["x"] for g in geo.values()]
    ys = [g["y"] for g in geo.values()] + [g["y"] + g["h"] for g in geo.values()]
    x_lo, x_hi = min(xs) - 1.4, max(xs) + W + 1.4
    y_lo, y_hi = min(ys) - 1.6, max(ys) + 0.9
    scale = 0.62
    fig = Figure(figsize=(max(4.0, (x_hi - x_lo) * scale), max(2.5, (y_hi - y_lo) * scale)))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_lo, y_hi)
    ax.set_aspect("equal")
    ax.axis("off")

    def port_xy(nd, port, side):
        gm = geo[nd]
        lst = gm["ins"] if side == "in" else gm["outs"]
        k = lst.index(port)
        y = gm["y"] + gm["h"] - 0.62 - PH * k - PH / 2
        return (gm["x"] if side == "in" else gm["x"] + W), y

    # subsystem frames (drawn first, under the blocks)
    subs = sorted({nd.rsplit(".", k)[0] for nd in names for k in range(1, nd.count(".") + 1)},
                  key=lambda s: -s.count("."))
    top_depth = max((sp.count(".") for sp in subs), default=0)
    for sp in subs:
        mem = [geo[nd] for nd in names if nd.startswith(sp + ".")]
        pad = 0.22 + 0.18 * (top_depth - sp.count("."))
        xa = min(m["x"] for m in mem) - pad
        xb = max(m["x"] for m in mem) + W + pad
        ya = min(m["y"] for m in mem) - pad
        yb = max(m["y"] + m["h"] for m in mem) + pad + 0.25
        r = Rectangle((xa, ya), xb - xa, yb - ya, fill=False, ls="--", ec="#7a8699",
                      lw=1.0, zorder=0)
        r.set_gid(f"subsystem {sp}")
        ax.add_patch(r)
        ax.text(xa + 0.1, yb - 0.08, sp, va="top", ha="left", fontsize=8, color="#4a5568",
                style="italic")
    for nd, gm in geo.items():
        box = FancyBboxPatch((gm["x"], gm["y"]), W, gm["h"], boxstyle="round,pad=0.02",
                             fc="#e8eef7", ec="#33475b", lw=1.2, zorder=2)
        box.set_gid(f"block {nd}")
        ax.add_patch(box)
        ax.text(gm["x"] + W / 2, gm["y"] + gm["h"] - 0.12, nd.rsplit(".", 1)[-1],
                ha="center", va="top", fontsize=10, fontweight="bold", zorder=3)
        ax.text(gm["x"] + W / 2, gm["y"] + gm["h"] - 0.42, type(gm["b"]).__name__,
                ha="center", va="top", fontsize=7, color="#555555", zorder=3)
        for p in gm["ins"]:
            x, y = port_xy(nd, p, "in")
            ax.plot([x], [y], marker=">", ms=5, color="#33475b", zorder=3)
            ax.text(x + 0.12, y, p, ha="left", va="center", fontsize=8, zorder=3)
        for p in gm["outs"]:
            x, y = port_xy(nd, p, "out")
            ax.plot([x], [y], marker=">", ms=5, color="#33475b", zorder=3)
            ax.text(x - 0.12, y, p, ha="right", va="center", fontsize=8, zorder=3)
    from matplotlib.path import Path as MplPath
    bottom = min(g["y"] for g in geo.values())
    nback = 0
    columns: dict[int, list] = {}
    for gm in geo.values():
        columns.setdefault(int(round(gm["x"] / DX)), []).append((gm["y"], gm["y"] + gm["h"]))
    used: dict[tuple, int] = {}

    def through(col, y_want):
        """A height at which a wire crosses column ``col`` clear of its
        blocks: the free gap nearest ``y_want`` (wires sharing a gap are
        spread apart)."""
        spans = sorted(columns.get(col, []))
        gaps = [spans[0][0] - 0.35] if spans else [y_want]
        gaps += [(hi + lo2) / 2 for (_lo, hi), (lo2, _hi) in zip(spans, spans[1:])]
        if spans:
            gaps.append(spans[-1][1] + 0.35)
        y = min(gaps, key=lambda g: abs(g - y_want))
        k = used.get((col, y), 0)
        used[(col, y)] = k + 1
        return y + 0.14 * ((k + 1) // 2) * (1 if k % 2 else -1)

    for (sp, so), (dp, di) in wires:
        a = np.array(port_xy(sp, so, "out"))
        b = np.array(port_xy(dp, di, "in"))
        if b[0] > a[0] + 0.3:                   # forward: S curves, around the
            la, lb = layer[sp], layer[dp]       # blocks of the columns it skips
            pts = [a]
            for col in range(la + 1, lb):
                y = through(col, a[1] + (b[1] - a[1]) * (col - la) / (lb - la))
                pts += [np.array([col * DX - 0.3, y]), np.array([col * DX + W + 0.3, y])]
            pts.append(b)
            verts, codes = [pts[0]], [MplPath.MOVETO]
            for i, (p, q) in enumerate(zip(pts, pts[1:])):
                if i % 2:                       # straight across a column
                    verts.append(q)
                    codes.append(MplPath.LINETO)
                else:
                    dx = (q[0] - p[0]) / 2
                    verts += [p + [dx, 0], q - [dx, 0], q]
                    codes += [MplPath.CURVE4] * 3
            path = MplPath(verts, codes)
            c1, c2 = verts[1], verts[2]         # label on the first curve
            a_lab, b_lab = verts[0], verts[3]
        else:                                   # feedback: a channel under the blocks
            ch = bottom - 0.5 - 0.22 * nback
            nback += 1
            pts = [a, a + [0.35, 0], [a[0] + 0.35, ch], [b[0] - 0.35, ch], b - [0.35, 0], b]
            path = MplPath(pts)
            c1 = c2 = np.array([(a[0] + b[0]) / 2, ch])    # label on the channel
            a_lab, b_lab = a, b
        arr = FancyArrowPatch(path=path, arrowstyle="-|>", mutation_scale=10, lw=1.1,
                              color="#33475b", shrinkA=1, shrinkB=3, zorder=1)
        arr.set_gid(f"wire {sp}.{so} -> {dp}.{di}")
        ax.add_patch(arr)
        spec = _ports_out(blocks[names.index(sp)]).get(so)
        mid = ((a_lab + 3 * c1 + 3 * c2 + b_lab) / 8 if path.codes is not None
               else c1)
        ax.text(mid[0], mid[1] + 0.04, _shape_text(spec), ha="center", va="bottom",
                fontsize=7, color="#33475b", zorder=4,
                bbox=dict(fc="white", ec="none", alpha=0.8, pad=0.5))
    return fig
