// Document -> React Flow nodes and edges (pure; the canvas draws what this returns).

import type { Doc, Palette, PortDecl, Validation, ValidationError, Wire, XY } from './types';
import type { Pt } from './router';
import type { Box, Route, WireEnds, Wiring } from './routes';
import { declOf, groupPorts, groupsOf, itemsAt, portsOf, refBlock, splitRef, visibleOwner } from './model';

export const NODE_W = 210;
export const HEADER_H = 34;
export const ROW_H = 22;

/** A handle's centre is on the block's border; React Flow's wire ends are its outer edge. */
export const HANDLE_OUT = 7;

export const IN_NODE = '__in';
export const OUT_NODE = '__out';

const textLen = (p: PortView) => p.label.length + (p.shape ? p.shape.length + 1 : 0);

/** Wide enough for the longest input and output row side by side, and the title. */
export function nodeWidth(inputs: PortView[], outputs: PortView[], title = ''): number {
  const li = Math.max(0, ...inputs.map(textLen));
  const lo = Math.max(0, ...outputs.map(textLen));
  const w = Math.max(6.6 * (li + lo) + 48, 7 * title.length + 40);
  return Math.max(NODE_W, Math.min(420, Math.ceil(w / 10) * 10));
}

export function nodeHeight(nIn: number, nOut: number): number {
  return HEADER_H + Math.max(1, nIn, nOut) * ROW_H + 10;
}

export interface PortView {
  id: string; // handle id
  label: string;
  shape?: string;
  unit?: string | null;
  doc?: string;
  errors: string[];
  driven?: boolean;
}

export interface BlockData {
  kind: 'block';
  name: string;
  type: string;
  title: string;
  summary?: string;
  inputs: PortView[];
  outputs: PortView[];
  errors: string[];
  known: boolean;
  [k: string]: unknown;
}

export interface GroupData {
  kind: 'group';
  name: string;
  label: string;
  count: number;
  inputs: PortView[];
  outputs: PortView[];
  errors: string[];
  [k: string]: unknown;
}

export interface BoundaryData {
  kind: 'boundary';
  side: 'in' | 'out';
  ports: PortView[];
  [k: string]: unknown;
}

export type NodeData = BlockData | GroupData | BoundaryData;

export interface FlowNode {
  id: string;
  type: 'block' | 'subsystem' | 'boundary';
  position: { x: number; y: number };
  data: NodeData;
  selected?: boolean;
  width?: number;
  height?: number;
  className?: string;
  deletable?: boolean;
}

export interface EdgeData {
  wire: Wire;
  shape?: string;
  errors: string[];
  /** The routed path (routes.ts), absent until routed or when a port is not drawn. */
  route?: WireRoute;
  [k: string]: unknown;
}

export interface WireRoute {
  /** SVG path */
  d: string;
  /** junction dots this wire draws */
  dots: Pt[];
  /** where the wire's name is shown when hovered (middle of its longest run) */
  mid: Pt;
  /** bounds [x0, y0, x1, y1] (fitting the view keeps a wire that goes round in view) */
  box: [number, number, number, number];
  how: 'grid' | 'straight' | 'fallback';
}

export interface FlowEdge {
  id: string;
  source: string;
  target: string;
  sourceHandle: string;
  targetHandle: string;
  type: 'wire';
  data: EdgeData;
  selected?: boolean;
  className?: string;
}

export function wireId(w: Wire): string {
  return `${w[0]}->${w[1]}`;
}

function portView(decl: PortDecl | undefined, id: string, label: string): PortView {
  return { id, label, shape: decl?.shape, unit: decl?.unit, doc: decl?.doc, errors: [] };
}

export function sameWire(a: Wire | null | undefined, b: Wire): boolean {
  return !!a && a[0] === b[0] && a[1] === b[1];
}

/** Errors a validation gives about a block (and, when `port` is given, its port). */
function errorsFor(errors: ValidationError[], block: string, port?: string): string[] {
  return errors
    .filter((e) => e.block === block && (port === undefined ? !e.port : e.port === port))
    .map((e) => e.message);
}

export interface ToFlowOptions {
  level?: string | null;
  validation?: Validation | null;
  selected?: Set<string>;
  selectedEdges?: Set<string>;
  positions?: Record<string, XY>;
}

export function toFlow(doc: Doc, palette: Palette | null, opts: ToFlowOptions = {}): { nodes: FlowNode[]; edges: FlowEdge[] } {
  const level = opts.level ?? null;
  const val = opts.validation ?? null;
  const errors = val?.errors ?? [];
  const selected = opts.selected ?? new Set<string>();
  const layout = doc.editor?.layout ?? {};
  const groups = groupsOf(doc);
  const { blocks, groups: shownGroups } = itemsAt(doc, level);
  const nodes: FlowNode[] = [];
  const driven = new Set(doc.wires.map(([, b]) => b));

  // the signals the last check named, by block (once, not once per block: 500 blocks x 1000 signals)
  const signalPorts = new Map<string, string[]>();
  for (const ref of Object.keys(val?.signals ?? {})) {
    const [sb, sp] = splitRef(ref);
    if (!sp) continue;
    const l = signalPorts.get(sb);
    if (l) l.push(sp);
    else signalPorts.set(sb, [sp]);
  }

  // each block's wires and errors, found once
  const wiresOf = new Map<string, Wire[]>();
  for (const w of doc.wires) {
    for (const blk of new Set([splitRef(w[0])[0], splitRef(w[1])[0]])) {
      const l = wiresOf.get(blk);
      if (l) l.push(w);
      else wiresOf.set(blk, [w]);
    }
  }
  const errorsOf = new Map<string, ValidationError[]>();
  for (const e of errors) {
    if (!e.block) continue;
    const l = errorsOf.get(e.block);
    if (l) l.push(e);
    else errorsOf.set(e.block, [e]);
  }

  for (const name of blocks) {
    const b = doc.blocks[name];
    if (!b) continue;
    const decl = declOf(palette, b.type);
    const ports = portsOf({ ...doc, wires: wiresOf.get(name) ?? [] }, name, palette, val?.ports);
    const errors = errorsOf.get(name) ?? [];
    // ports the last check named (outputs with a signal, inputs an error is about)
    for (const sp of signalPorts.get(name) ?? []) {
      if (!ports.outputs.includes(sp) && !ports.inputs.includes(sp)) ports.outputs.push(sp);
    }
    for (const e of errors) {
      if (e.block === name && e.port && !ports.inputs.includes(e.port) && !ports.outputs.includes(e.port)) ports.inputs.push(e.port);
    }
    const inputs = ports.inputs.map((p) => {
      const v = portView(decl?.inputs.find((d) => d.name === p), p, p);
      v.errors = errorsFor(errors, name, p);
      v.driven = driven.has(`${name}.${p}`);
      return v;
    });
    const outputs = ports.outputs.map((p) => {
      const v = portView(decl?.outputs.find((d) => d.name === p), p, p);
      v.errors = errorsFor(errors, name, p);
      const sig = val?.signals?.[`${name}.${p}`];
      if (sig) v.shape = sig.shape;
      return v;
    });
    // errors naming a parameter are the block's
    const blockErrors = errors.filter((e) => e.block === name && (!e.port || !ports.inputs.concat(ports.outputs).includes(e.port))).map((e) => e.message);
    const p = opts.positions?.[name] ?? layout[name] ?? [0, 0];
    nodes.push({
      id: name,
      type: 'block',
      position: { x: p[0], y: p[1] },
      selected: selected.has(name),
      width: nodeWidth(inputs, outputs, `${decl?.name ?? b.type} ${name}`),
      height: nodeHeight(inputs.length, outputs.length),
      data: {
        kind: 'block',
        name,
        type: b.type,
        title: decl?.name ?? b.type.split('.').pop() ?? b.type,
        summary: decl?.summary,
        inputs,
        outputs,
        errors: blockErrors,
        known: !!decl,
      },
    });
  }

  for (const g of shownGroups) {
    const grp = groups[g];
    const gp = groupPorts(doc, g);
    const inside = (ref: string) => visibleOwner(doc, refBlock(ref), level) === g;
    const label = (ref: string) => ref;
    const inputs = gp.inputs.map((r) => {
      const [b, p] = splitRef(r);
      const v = portView(undefined, r, label(r));
      v.errors = errorsFor(errors, b, p);
      return v;
    });
    const outputs = gp.outputs.map((r) => {
      const v = portView(undefined, r, label(r));
      const sig = val?.signals?.[r];
      if (sig) v.shape = sig.shape;
      return v;
    });
    const groupErrors = errors.filter((e) => e.block && inside(`${e.block}.x`)).map((e) => e.message);
    const p = opts.positions?.[g] ?? grp.position ?? [0, 0];
    nodes.push({
      id: g,
      type: 'subsystem',
      position: { x: p[0], y: p[1] },
      selected: selected.has(g),
      width: nodeWidth(inputs, outputs, grp.label ?? g) + 40,
      height: nodeHeight(inputs.length, outputs.length) + 16,
      data: { kind: 'group', name: g, label: grp.label ?? g, count: blocks.length, inputs, outputs, errors: groupErrors },
    });
    (nodes[nodes.length - 1].data as GroupData).count = countBlocks(doc, g);
  }

  const edges: FlowEdge[] = [];
  const boundaryIn: PortView[] = [];
  const boundaryOut: PortView[] = [];
  const selectedEdges = opts.selectedEdges ?? new Set<string>();
  for (const w of doc.wires) {
    const [a, b] = w;
    const sa = visibleOwner(doc, refBlock(a), level);
    const sb = visibleOwner(doc, refBlock(b), level);
    if (sa === null && sb === null) continue;
    if (sa !== null && sa === sb && sa in groups) continue;
    let source: string;
    let sourceHandle: string;
    let target: string;
    let targetHandle: string;
    if (sa === null) {
      source = IN_NODE;
      sourceHandle = a;
      if (!boundaryIn.some((p) => p.id === a)) {
        const v = portView(undefined, a, a);
        v.shape = val?.signals?.[a]?.shape;
        boundaryIn.push(v);
      }
    } else {
      source = sa;
      sourceHandle = sa in groups ? a : splitRef(a)[1];
    }
    if (sb === null) {
      target = OUT_NODE;
      targetHandle = a;
      if (boundaryOut.some((p) => p.id === a)) continue;
      boundaryOut.push(portView(undefined, a, a));
    } else {
      target = sb;
      targetHandle = sb in groups ? b : splitRef(b)[1];
    }
    const wErrors = errors
      .filter((e) => sameWire(e.wire, w) || (e.cycle && e.cycle.includes(a) && e.cycle.includes(b)))
      .map((e) => e.message);
    const id = wireId(w);
    edges.push({
      id,
      source,
      target,
      sourceHandle,
      targetHandle,
      type: 'wire',
      selected: selectedEdges.has(id),
      data: { wire: w, shape: val?.signals?.[a]?.shape, errors: wErrors },
    });
  }

  if (level !== null) {
    const inner = nodes.filter((n) => n.type !== 'boundary');
    const minX = inner.length ? Math.min(...inner.map((n) => n.position.x)) : 0;
    const maxX = inner.length ? Math.max(...inner.map((n) => n.position.x + (n.width ?? NODE_W))) : 400;
    const minY = inner.length ? Math.min(...inner.map((n) => n.position.y)) : 0;
    nodes.push({
      id: IN_NODE,
      type: 'boundary',
      position: { x: minX - nodeWidth([], boundaryIn) - 100, y: minY },
      width: nodeWidth([], boundaryIn),
      height: nodeHeight(0, boundaryIn.length),
      deletable: false,
      data: { kind: 'boundary', side: 'in', ports: boundaryIn },
    });
    nodes.push({
      id: OUT_NODE,
      type: 'boundary',
      position: { x: maxX + 120, y: minY },
      width: nodeWidth(boundaryOut, []),
      height: nodeHeight(boundaryOut.length, 0),
      deletable: false,
      data: { kind: 'boundary', side: 'out', ports: boundaryOut },
    });
  }
  return { nodes, edges };
}

function countBlocks(doc: Doc, g: string): number {
  const grp = groupsOf(doc)[g];
  if (!grp) return 0;
  return grp.blocks.length + (grp.groups ?? []).reduce((s, x) => s + countBlocks(doc, x), 0);
}

/** The wire end a connection drawn between two handles means ("block.port"). */
export function handleRef(doc: Doc, node: string, handle: string): string {
  if (node in doc.blocks) return `${node}.${handle}`;
  return handle; // groups and boundary nodes carry full refs
}

function sameJson(a: unknown, b: unknown): boolean {
  return a === b || JSON.stringify(a) === JSON.stringify(b);
}

function sameNode(a: FlowNode, b: FlowNode): boolean {
  return (
    a.type === b.type &&
    a.position.x === b.position.x &&
    a.position.y === b.position.y &&
    !!a.selected === !!b.selected &&
    a.width === b.width &&
    a.height === b.height &&
    a.className === b.className &&
    a.deletable === b.deletable &&
    sameJson(a.data, b.data)
  );
}

function sameEdge(a: FlowEdge, b: FlowEdge): boolean {
  const da = a.data;
  const db = b.data;
  return (
    a.source === b.source &&
    a.target === b.target &&
    a.sourceHandle === b.sourceHandle &&
    a.targetHandle === b.targetHandle &&
    !!a.selected === !!b.selected &&
    a.className === b.className &&
    // a route is compared by identity (routed() keeps the object of one that did not change)
    da.route === db.route &&
    da.shape === db.shape &&
    da.wire[0] === db.wire[0] &&
    da.wire[1] === db.wire[1] &&
    sameJson(da.errors, db.errors)
  );
}

/** `next` with each node and edge equal to one of `prev` replaced by that object (the same
 * identity: React Flow's memoised node and edge components then skip it). The arrays are
 * `prev`'s own when nothing changed at all. */
export function stableFlow(prev: { nodes: FlowNode[]; edges: FlowEdge[] }, next: { nodes: FlowNode[]; edges: FlowEdge[] }): { nodes: FlowNode[]; edges: FlowEdge[] } {
  const oldNodes = new Map(prev.nodes.map((n) => [n.id, n]));
  const oldEdges = new Map(prev.edges.map((e) => [e.id, e]));
  const nodes = next.nodes.map((n) => {
    const o = oldNodes.get(n.id);
    return o && sameNode(o, n) ? o : n;
  });
  const edges = next.edges.map((e) => {
    const o = oldEdges.get(e.id);
    return o && sameEdge(o, e) ? o : e;
  });
  const same = <T,>(a: T[], b: T[]) => a.length === b.length && a.every((x, i) => x === b[i]);
  return { nodes: same(nodes, prev.nodes) ? prev.nodes : nodes, edges: same(edges, prev.edges) ? prev.edges : edges };
}

/** Where a wire meets a port handle (the same point React Flow ends its wires at). */
export function portPoint(n: FlowNode, handle: string, side: 'in' | 'out'): Pt | null {
  const d = n.data;
  let list: PortView[];
  if (d.kind === 'boundary') list = (d.side === 'in') === (side === 'out') ? d.ports : [];
  else list = side === 'in' ? d.inputs : d.outputs;
  const i = list.findIndex((p) => p.id === handle);
  if (i < 0) return null;
  const y = n.position.y + HEADER_H + i * ROW_H + ROW_H / 2 + 4;
  return side === 'out' ? [n.position.x + (n.width ?? NODE_W) + HANDLE_OUT, y] : [n.position.x - HANDLE_OUT, y];
}

/** The blocks and the wire ends of a flow, for the router. */
export function routeInputs(nodes: FlowNode[], edges: FlowEdge[]): { boxes: Box[]; wires: WireEnds[] } {
  const byId = new Map(nodes.map((n) => [n.id, n]));
  const boxes: Box[] = nodes.map((n) => ({ id: n.id, x: n.position.x, y: n.position.y, w: n.width ?? NODE_W, h: n.height ?? 60 }));
  const wires: WireEnds[] = [];
  for (const e of edges) {
    const a = byId.get(e.source);
    const b = byId.get(e.target);
    const from = a ? portPoint(a, e.sourceHandle, 'out') : null;
    const to = b ? portPoint(b, e.targetHandle, 'in') : null;
    if (from && to) wires.push({ id: e.id, net: `${e.source}\u0000${e.sourceHandle}`, source: e.source, target: e.target, from, to });
  }
  return { boxes, wires };
}

function routeView(r: Route): WireRoute {
  let best = -1;
  let mid: Pt = r.points[0];
  let x0 = Infinity;
  let y0 = Infinity;
  let x1 = -Infinity;
  let y1 = -Infinity;
  r.points.forEach((p, i) => {
    x0 = Math.min(x0, p[0]);
    y0 = Math.min(y0, p[1]);
    x1 = Math.max(x1, p[0]);
    y1 = Math.max(y1, p[1]);
    const q = r.points[i + 1];
    if (!q) return;
    const len = Math.abs(q[0] - p[0]) + Math.abs(q[1] - p[1]);
    if (len > best) {
      best = len;
      mid = [(p[0] + q[0]) / 2, (p[1] + q[1]) / 2];
    }
  });
  return { d: r.d, dots: r.dots, mid, box: [x0, y0, x1, y1], how: r.how };
}

const views = new WeakMap<Route, WireRoute>();

/** The flow with each wire's route (a wire whose ports are not drawn keeps none). A route
 * that did not change keeps its view object, which tells stableFlow the wire is the same. */
export function routed(flow: { nodes: FlowNode[]; edges: FlowEdge[] }, wiring: Wiring): { nodes: FlowNode[]; edges: FlowEdge[] } {
  const { boxes, wires } = routeInputs(flow.nodes, flow.edges);
  const routes = wiring.update(boxes, wires);
  for (const e of flow.edges) {
    const r = routes.get(e.id);
    if (!r) continue;
    let v = views.get(r);
    if (!v) views.set(r, (v = routeView(r)));
    e.data.route = v; // (toFlow's objects are new: set in place)
  }
  return flow;
}
