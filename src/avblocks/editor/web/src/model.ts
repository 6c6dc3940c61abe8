// The document model: pure functions over the scenario document (no React).
//
// Every function takes a document and returns a new one; the input is never
// changed, so the undo history can keep old documents as they are.

import type { Block, BlockDecl, Doc, Group, Json, Palette, Wire, XY } from './types';

export const NAME_RE = /^[A-Za-z_][A-Za-z0-9_]*$/;

export class ModelError extends Error {}

// ---------------------------------------------------------------- basics

export function emptyDocument(name = 'untitled'): Doc {
  return {
    name,
    parameters: { agents: 15, seed: 1 },
    blocks: {},
    wires: [],
    simulation: { t_final: 30, dt: 0.02 },
    editor: { layout: {}, groups: {} },
  };
}

/** Split "block.port" at its first dot. */
export function splitRef(ref: string): [string, string] {
  const i = ref.indexOf('.');
  if (i < 0) return [ref, ''];
  return [ref.slice(0, i), ref.slice(i + 1)];
}

export function refBlock(ref: string): string {
  return splitRef(ref)[0];
}

function editorOf(doc: Doc) {
  const e = doc.editor ?? {};
  return { layout: { ...(e.layout ?? {}) }, groups: { ...(e.groups ?? {}) }, viewport: e.viewport };
}

function withEditor(doc: Doc, layout: Record<string, XY>, groups: Record<string, Group>): Doc {
  const editor: Doc['editor'] = { ...(doc.editor ?? {}), layout, groups };
  return { ...doc, editor };
}

export function uniqueName(doc: Doc, base: string, taken: Set<string> = new Set()): string {
  let stem = base.replace(/[^A-Za-z0-9_]/g, '_').replace(/^(\d)/, '_$1') || 'block';
  stem = stem.replace(/\d+$/, '') || stem;
  const used = (n: string) => n in doc.blocks || n in (doc.editor?.groups ?? {}) || taken.has(n);
  if (!used(stem)) return stem;
  for (let i = 2; ; i++) if (!used(`${stem}${i}`)) return `${stem}${i}`;
}

export function defaultNameFor(type: string): string {
  const short = type.split('.').pop() ?? type;
  // CamelCase -> snake_case: "PointToPoint" -> "point_to_point"
  return short.replace(/([a-z0-9])([A-Z])/g, '$1_$2').replace(/([A-Z])([A-Z][a-z])/g, '$1_$2').toLowerCase();
}

// ---------------------------------------------------------------- blocks

export function addBlock(
  doc: Doc,
  type: string,
  opts: { template?: Record<string, Json>; name?: string; position?: XY } = {},
): { doc: Doc; name: string } {
  const name = opts.name ?? uniqueName(doc, defaultNameFor(type));
  if (!NAME_RE.test(name)) throw new ModelError(`'${name}' is not a valid block name`);
  if (name in doc.blocks) throw new ModelError(`a block named '${name}' exists`);
  const block: Block = { type, ...structuredClone(opts.template ?? {}) };
  const { layout, groups } = editorOf(doc);
  if (opts.position) layout[name] = [Math.round(opts.position[0]), Math.round(opts.position[1])];
  return { doc: withEditor({ ...doc, blocks: { ...doc.blocks, [name]: block } }, layout, groups), name };
}

/** Remove blocks (and groups named in `names`, with their contents), their wires and layout. */
export function removeItems(doc: Doc, names: Iterable<string>): Doc {
  const { layout, groups } = editorOf(doc);
  const drop = new Set<string>();
  const dropGroups = new Set<string>();
  const visit = (n: string) => {
    if (n in groups) {
      dropGroups.add(n);
      for (const b of groups[n].blocks) drop.add(b);
      for (const g of groups[n].groups ?? []) visit(g);
    } else drop.add(n);
  };
  for (const n of names) visit(n);
  const blocks: Record<string, Block> = {};
  for (const [k, v] of Object.entries(doc.blocks)) if (!drop.has(k)) blocks[k] = v;
  const wires = doc.wires.filter(([a, b]) => !drop.has(refBlock(a)) && !drop.has(refBlock(b)));
  for (const n of drop) delete layout[n];
  const newGroups: Record<string, Group> = {};
  for (const [g, grp] of Object.entries(groups)) {
    if (dropGroups.has(g)) continue;
    newGroups[g] = {
      ...grp,
      blocks: grp.blocks.filter((b) => !drop.has(b)),
      ...(grp.groups ? { groups: grp.groups.filter((x) => !dropGroups.has(x)) } : {}),
    };
  }
  return withEditor({ ...doc, blocks, wires }, layout, newGroups);
}

export function renameBlock(doc: Doc, from: string, to: string): Doc {
  if (from === to) return doc;
  if (!(from in doc.blocks)) throw new ModelError(`no block named '${from}'`);
  if (!NAME_RE.test(to)) throw new ModelError(`'${to}' is not a valid name (letters, digits, _; not starting with a digit)`);
  if (to in doc.blocks || to in (doc.editor?.groups ?? {})) throw new ModelError(`the name '${to}' is taken`);
  const blocks: Record<string, Block> = {};
  for (const [k, v] of Object.entries(doc.blocks)) blocks[k === from ? to : k] = v;
  const ren = (ref: string) => {
    const [b, p] = splitRef(ref);
    return b === from ? `${to}.${p}` : ref;
  };
  const wires = doc.wires.map(([a, b]) => [ren(a), ren(b)] as Wire);
  const { layout, groups } = editorOf(doc);
  if (from in layout) {
    layout[to] = layout[from];
    delete layout[from];
  }
  for (const [g, grp] of Object.entries(groups))
    groups[g] = { ...grp, blocks: grp.blocks.map((b) => (b === from ? to : b)) };
  // logged signals name blocks too
  let simulation = doc.simulation;
  if (simulation && Array.isArray(simulation.log))
    simulation = { ...simulation, log: (simulation.log as Json[]).map((s) => (typeof s === 'string' ? ren(s) : s)) };
  return withEditor({ ...doc, blocks, wires, simulation }, layout, groups);
}

/** Set (or, with `undefined`, remove) one argument of a block. */
export function setParam(doc: Doc, block: string, key: string, value: Json | undefined): Doc {
  const b = doc.blocks[block];
  if (!b) throw new ModelError(`no block named '${block}'`);
  if (key === 'type') throw new ModelError('the type of a block is not a parameter');
  const nb: Block = { ...b };
  if (value === undefined) delete nb[key];
  else nb[key] = value;
  return { ...doc, blocks: { ...doc.blocks, [block]: nb } };
}

/** Set (or remove) one diagram parameter (`parameters:` of the scenario). */
export function setDiagramParameter(doc: Doc, key: string, value: Json | undefined): Doc {
  const parameters = { ...(doc.parameters ?? {}) };
  if (value === undefined) delete parameters[key];
  else parameters[key] = value;
  return { ...doc, parameters };
}

export function setSimulation(doc: Doc, key: string, value: Json | undefined): Doc {
  const simulation = { ...(doc.simulation ?? {}) };
  if (value === undefined) delete simulation[key];
  else simulation[key] = value;
  return { ...doc, simulation };
}

export function moveItems(doc: Doc, positions: Record<string, XY>): Doc {
  const { layout, groups } = editorOf(doc);
  for (const [n, p] of Object.entries(positions)) {
    const xy: XY = [Math.round(p[0]), Math.round(p[1])];
    if (n in groups) groups[n] = { ...groups[n], position: xy };
    else layout[n] = xy;
  }
  return withEditor(doc, layout, groups);
}

// ---------------------------------------------------------------- wires

export interface ConnectResult {
  doc: Doc;
  /** The wire that drove the input before and was replaced (one driver per input). */
  replaced: Wire | null;
  added: boolean;
}

/** Wire an output `from` ("block.port") to an input `to`; an input has one driver, so a wire already into `to` is replaced. */
export function connect(doc: Doc, from: string, to: string): ConnectResult {
  const [fb] = splitRef(from);
  const [tb] = splitRef(to);
  if (!(fb in doc.blocks)) throw new ModelError(`no block named '${fb}'`);
  if (!(tb in doc.blocks)) throw new ModelError(`no block named '${tb}'`);
  const existing = doc.wires.find(([, b]) => b === to) ?? null;
  if (existing && existing[0] === from) return { doc, replaced: null, added: false };
  const wires = doc.wires.filter(([, b]) => b !== to);
  wires.push([from, to]);
  return { doc: { ...doc, wires }, replaced: existing, added: true };
}

export function disconnect(doc: Doc, wire: Wire): Doc {
  return { ...doc, wires: doc.wires.filter(([a, b]) => !(a === wire[0] && b === wire[1])) };
}

export function driverOf(doc: Doc, input: string): string | null {
  const w = doc.wires.find(([, b]) => b === input);
  return w ? w[0] : null;
}

// ---------------------------------------------------------------- groups

export function groupsOf(doc: Doc): Record<string, Group> {
  return doc.editor?.groups ?? {};
}

/** The group that directly contains item `name` (block or group), or null at the top. */
export function parentOf(doc: Doc, name: string): string | null {
  for (const [g, grp] of Object.entries(groupsOf(doc))) {
    if (grp.blocks.includes(name) || (grp.groups ?? []).includes(name)) return g;
  }
  return null;
}

/** Every block inside group `g`, nested groups included. */
export function blocksIn(doc: Doc, g: string): string[] {
  const grp = groupsOf(doc)[g];
  if (!grp) return [];
  return [...grp.blocks, ...(grp.groups ?? []).flatMap((s) => blocksIn(doc, s))];
}

/** Items (blocks and groups) shown at a level: the top (`null`) or inside a group. */
export function itemsAt(doc: Doc, level: string | null): { blocks: string[]; groups: string[] } {
  const groups = groupsOf(doc);
  if (level !== null) {
    const grp = groups[level];
    return { blocks: grp ? [...grp.blocks] : [], groups: grp ? [...(grp.groups ?? [])] : [] };
  }
  return {
    blocks: Object.keys(doc.blocks).filter((b) => parentOf(doc, b) === null),
    groups: Object.keys(groups).filter((g) => parentOf(doc, g) === null),
  };
}

/** The item at `level` that shows block `b` (the block itself or the group holding it), or null when it is not inside `level`. */
export function visibleOwner(doc: Doc, b: string, level: string | null): string | null {
  let cur: string = b;
  for (;;) {
    const p = parentOf(doc, cur);
    if (p === level) return cur;
    if (p === null) return null;
    cur = p;
  }
}

export interface GroupPorts {
  /** Inner inputs fed from outside: "block.port" of the inner input. */
  inputs: string[];
  /** Inner outputs read outside: "block.port" of the inner output. */
  outputs: string[];
}

/** A group's ports are the wires its boundary cuts. */
export function groupPorts(doc: Doc, g: string): GroupPorts {
  const inside = new Set(blocksIn(doc, g));
  const inputs: string[] = [];
  const outputs: string[] = [];
  for (const [a, b] of doc.wires) {
    const ai = inside.has(refBlock(a));
    const bi = inside.has(refBlock(b));
    if (!ai && bi && !inputs.includes(b)) inputs.push(b);
    if (ai && !bi && !outputs.includes(a)) outputs.push(a);
  }
  return { inputs, outputs };
}

/** Make a group of `items` (blocks and groups at one level); returns its name. */
export function groupItems(doc: Doc, items: string[], opts: { name?: string; label?: string } = {}): { doc: Doc; name: string } {
  if (items.length === 0) throw new ModelError('select blocks to group');
  const { layout, groups } = editorOf(doc);
  const parents = new Set(items.map((i) => parentOf(doc, i)));
  if (parents.size > 1) throw new ModelError('the items to group are at different levels');
  const parent = [...parents][0];
  const name = opts.name ?? uniqueName(doc, 'group');
  if (!NAME_RE.test(name) || name in doc.blocks || name in groups) throw new ModelError(`the name '${name}' is taken or not valid`);
  const blocks = items.filter((i) => i in doc.blocks);
  const subs = items.filter((i) => i in groups);
  const xs: XY[] = items.map((i) => (i in groups ? groups[i].position : layout[i])).filter((p): p is XY => !!p);
  const position: XY = xs.length
    ? [Math.round(xs.reduce((s, p) => s + p[0], 0) / xs.length), Math.round(xs.reduce((s, p) => s + p[1], 0) / xs.length)]
    : [0, 0];
  const grp: Group = { blocks, position, label: opts.label ?? name };
  if (subs.length) grp.groups = subs;
  if (parent !== null) {
    const pg = groups[parent];
    groups[parent] = {
      ...pg,
      blocks: pg.blocks.filter((b) => !blocks.includes(b)),
      groups: [...(pg.groups ?? []).filter((x) => !subs.includes(x)), name],
    };
  }
  groups[name] = grp;
  return { doc: withEditor(doc, layout, groups), name };
}

/** Dissolve a group: its contents go to the level that held it. */
export function ungroup(doc: Doc, g: string): Doc {
  const { layout, groups } = editorOf(doc);
  const grp = groups[g];
  if (!grp) throw new ModelError(`no group named '${g}'`);
  const parent = parentOf(doc, g);
  delete groups[g];
  if (parent !== null) {
    const pg = groups[parent];
    groups[parent] = {
      ...pg,
      blocks: [...pg.blocks, ...grp.blocks],
      groups: [...(pg.groups ?? []).filter((x) => x !== g), ...(grp.groups ?? [])],
    };
  }
  return withEditor(doc, layout, groups);
}

export function renameGroupLabel(doc: Doc, g: string, label: string): Doc {
  const { layout, groups } = editorOf(doc);
  if (!groups[g]) throw new ModelError(`no group named '${g}'`);
  groups[g] = { ...groups[g], label };
  return withEditor(doc, layout, groups);
}

// ---------------------------------------------------------------- copy / paste

export interface Fragment {
  blocks: Record<string, Block>;
  wires: Wire[];
  layout: Record<string, XY>;
}

/** The blocks named (groups expand to their blocks) and the wires among them. */
export function copyItems(doc: Doc, items: string[]): Fragment {
  const names = new Set<string>();
  for (const i of items) {
    if (i in groupsOf(doc)) blocksIn(doc, i).forEach((b) => names.add(b));
    else if (i in doc.blocks) names.add(i);
  }
  const blocks: Record<string, Block> = {};
  const layout: Record<string, XY> = {};
  for (const n of names) {
    blocks[n] = structuredClone(doc.blocks[n]);
    const p = doc.editor?.layout?.[n];
    if (p) layout[n] = [p[0], p[1]];
  }
  const wires = doc.wires.filter(([a, b]) => names.has(refBlock(a)) && names.has(refBlock(b))).map((w) => [...w] as Wire);
  return { blocks, wires, layout };
}

/** Paste a fragment: blocks get fresh names where theirs are taken; positions shift by `offset`. */
export function paste(doc: Doc, frag: Fragment, offset: XY = [40, 40], level: string | null = null): { doc: Doc; names: string[] } {
  const rename: Record<string, string> = {};
  const taken = new Set<string>();
  for (const n of Object.keys(frag.blocks)) {
    const nn = uniqueName(doc, n, taken);
    rename[n] = nn;
    taken.add(nn);
  }
  const blocks = { ...doc.blocks };
  const { layout, groups } = editorOf(doc);
  for (const [n, b] of Object.entries(frag.blocks)) {
    blocks[rename[n]] = structuredClone(b);
    const p = frag.layout[n];
    if (p) layout[rename[n]] = [p[0] + offset[0], p[1] + offset[1]];
  }
  const ren = (ref: string) => {
    const [b, p] = splitRef(ref);
    return `${rename[b]}.${p}`;
  };
  const wires = [...doc.wires, ...frag.wires.map(([a, b]) => [ren(a), ren(b)] as Wire)];
  const names = Object.values(rename);
  if (level !== null && groups[level]) groups[level] = { ...groups[level], blocks: [...groups[level].blocks, ...names] };
  return { doc: withEditor({ ...doc, blocks, wires }, layout, groups), names };
}

// ---------------------------------------------------------------- ports

export interface Ports {
  inputs: string[];
  outputs: string[];
}

export function declOf(palette: Palette | null, type: string): BlockDecl | null {
  if (!palette) return null;
  for (const f of palette.families) for (const b of f.blocks) if (b.type === type) return b;
  return null;
}

/**
 * The ports a block instance shows: the declared ones, the ones the last
 * validation reported, and any port a wire names (blocks whose ports depend on
 * their parameters, e.g. a Supervisor's `inputs`/`outputs`), so nothing drawn is lost.
 */
export function portsOf(doc: Doc, name: string, palette: Palette | null, built?: Record<string, Ports>): Ports {
  const b = doc.blocks[name];
  const decl = b ? declOf(palette, b.type) : null;
  const inputs: string[] = decl ? decl.inputs.map((p) => p.name) : [];
  const outputs: string[] = decl ? decl.outputs.map((p) => p.name) : [];
  const add = (list: string[], p: string) => {
    if (p && !list.includes(p)) list.push(p);
  };
  const bp = built?.[name];
  if (bp) {
    bp.inputs.forEach((p) => add(inputs, p));
    bp.outputs.forEach((p) => add(outputs, p));
  }
  // parameter-declared ports (a mapping of port name -> shape)
  if (b) {
    for (const [key, list] of [['inputs', inputs], ['outputs', outputs]] as const) {
      const v = b[key];
      if (v && typeof v === 'object' && !Array.isArray(v)) Object.keys(v).forEach((p) => add(list, p));
    }
  }
  for (const [a, c] of doc.wires) {
    const [ab, ap] = splitRef(a);
    const [cb, cp] = splitRef(c);
    if (ab === name) add(outputs, ap);
    if (cb === name) add(inputs, cp);
  }
  return { inputs, outputs };
}

// ---------------------------------------------------------------- history

export interface History {
  past: Doc[];
  present: Doc;
  future: Doc[];
  /** Edits with the same key in a row (typing in one field) make one undo step. */
  lastKey?: string | null;
}

export const HISTORY_LIMIT = 200;

export function history(doc: Doc): History {
  return { past: [], present: doc, future: [], lastKey: null };
}

export function commit(h: History, doc: Doc, key: string | null = null): History {
  if (doc === h.present) return h;
  if (key !== null && key === h.lastKey) return { ...h, present: doc, future: [] };
  const past = [...h.past, h.present].slice(-HISTORY_LIMIT);
  return { past, present: doc, future: [], lastKey: key };
}

/** Replace the present without an undo step (drag in progress, validation-free bookkeeping). */
export function replace(h: History, doc: Doc): History {
  return { ...h, present: doc };
}

export function undo(h: History): History {
  if (!h.past.length) return h;
  return { past: h.past.slice(0, -1), present: h.past[h.past.length - 1], future: [h.present, ...h.future], lastKey: null };
}

export function redo(h: History): History {
  if (!h.future.length) return h;
  return { past: [...h.past, h.present], present: h.future[0], future: h.future.slice(1), lastKey: null };
}

// ---------------------------------------------------------------- values

/** A parameter value as text in a field (JSON with bare `$name` references). */
export function valueToText(v: Json | undefined): string {
  if (v === undefined) return '';
  if (typeof v === 'string') return v;
  return flowText(v);
}

const BARE = /^\$?[A-Za-z_][A-Za-z0-9_]*$/;

/** How a number that JSON cannot write is written (as YAML writes it). */
function numberText(v: number): string {
  if (Number.isNaN(v)) return '.nan';
  if (v === Infinity) return '.inf';
  if (v === -Infinity) return '-.inf';
  return JSON.stringify(v);
}

function flowText(v: Json): string {
  if (typeof v === 'number') return numberText(v);
  if (v === null || typeof v === 'boolean') return JSON.stringify(v);
  if (typeof v === 'string') return BARE.test(v) && !['true', 'false', 'null'].includes(v) ? v : JSON.stringify(v);
  if (Array.isArray(v)) return `[${v.map(flowText).join(', ')}]`;
  return `{${Object.entries(v)
    .map(([k, x]) => `${BARE.test(k) ? k : JSON.stringify(k)}: ${flowText(x)}`)
    .join(', ')}}`;
}

/** Parse a field's text: JSON, where `$name` and bare words may go unquoted. Throws ModelError. */
export function parseValue(text: string): Json {
  const t = text.trim();
  if (t === '') throw new ModelError('empty');
  const special = nonFinite(t);
  if (special !== null) return special;
  try {
    return JSON.parse(t) as Json;
  } catch {
    /* try the relaxed form */
  }
  if (/^\$[A-Za-z_][A-Za-z0-9_]*$/.test(t)) return t;
  if (!/^[[{]/.test(t)) {
    if (/^[A-Za-z_][A-Za-z0-9_.\-]*$/.test(t)) return t; // a bare word: a string
    throw new ModelError(`cannot read '${t}' (numbers, [lists], {"mappings"} or $parameter)`);
  }
  // quote $refs and bare keys / words; the numbers JSON cannot write become markers
  const marks: number[] = [];
  const quoted = t.replace(/("(?:[^"\\]|\\.)*")|(-?\.(?:nan|NaN|NAN|inf|Inf|INF)\b)|(-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(\$?[A-Za-z_][A-Za-z0-9_]*)/g, (m, str, yaml, number, word) => {
    if (str) return str;
    if (yaml || number) {
      const f = nonFinite(yaml ?? number);
      if (f === null) return number;
      marks.push(f);
      return `{"\\u0000": ${marks.length - 1}}`;
    }
    if (word === 'true' || word === 'false' || word === 'null') return word;
    const f = nonFinite(word);
    if (f !== null) {
      marks.push(f);
      return `{"\\u0000": ${marks.length - 1}}`;
    }
    return JSON.stringify(word);
  });
  let v: Json;
  try {
    v = JSON.parse(quoted) as Json;
  } catch (e) {
    throw new ModelError(`not a value: ${(e as Error).message}`);
  }
  return unmark(v, marks);
}

/** A number too large for a float (1e999) or written as YAML writes NaN and infinity
 * (.nan, .inf, -.inf; also nan, inf, Infinity): the number, which the library will judge;
 * null for any other text. */
export function nonFinite(t: string): number | null {
  if (/^[-+]?\.?(nan|NaN|NAN)$/.test(t)) return NaN;
  const m = /^([-+]?)\.?(inf|Inf|INF|infinity|Infinity)$/.exec(t);
  if (m) return m[1] === '-' ? -Infinity : Infinity;
  if (/^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/.test(t)) {
    const v = Number(t);
    if (!Number.isFinite(v)) return v;
  }
  return null;
}

function unmark(v: Json, marks: number[]): Json {
  if (Array.isArray(v)) return v.map((x) => unmark(x, marks));
  if (v && typeof v === 'object') {
    const keys = Object.keys(v);
    if (keys.length === 1 && keys[0] === '\u0000') return marks[(v as Record<string, number>)['\u0000']];
    const out: Record<string, Json> = {};
    for (const k of keys) out[k] = unmark((v as Record<string, Json>)[k], marks);
    return out;
  }
  return v;
}

/** A one-key mapping naming a known generator, e.g. {"random_poses": {...}}. */
export function generatorOf(v: Json | undefined, names: string[]): { name: string; args: Record<string, Json> } | null {
  if (!v || typeof v !== 'object' || Array.isArray(v)) return null;
  const keys = Object.keys(v);
  if (keys.length !== 1 || !names.includes(keys[0])) return null;
  const args = (v as Record<string, Json>)[keys[0]];
  return { name: keys[0], args: args && typeof args === 'object' && !Array.isArray(args) ? (args as Record<string, Json>) : {} };
}
