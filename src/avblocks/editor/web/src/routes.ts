// The wires of one canvas level routed together (pure: no React; tested with Vitest).
//
// `Wiring.update(boxes, wires)` routes each wire with router.ts among the blocks near it,
// reusing the last route of a wire whose ends and neighbouring blocks did not move (a drag
// re-routes the wires near the dragged block, not all of them). Then, over all routes:
//
// * nudging: wires of different nets that would run on the same line side by side are
//   spread a few pixels apart (never more than the clearance, so never into a block);
// * junctions: where wires of one net (one output port) part, a dot;
// * crossings: where a horizontal run crosses a vertical run of another net, the
//   horizontal one hops over it (a small arc), so a crossing never reads as a junction.

import { DEFAULTS, padRect, routeWire, segmentHits } from './router';
import type { Pt, Rect, RouterOptions } from './router';

export interface Box extends Rect {
  id: string;
}

export interface WireEnds {
  id: string;
  /** The net: wires from one output port share it ("node:handle"). */
  net: string;
  source: string;
  target: string;
  from: Pt;
  to: Pt;
}

export interface Hop {
  x: number;
  y: number;
}

export interface Route {
  id: string;
  net: string;
  points: Pt[];
  /** Where the wire hops over others (on its horizontal runs). */
  hops: Hop[];
  /** Junction dots this wire draws (one wire of each net draws them). */
  dots: Pt[];
  how: 'grid' | 'straight' | 'fallback';
  /** The SVG path. */
  d: string;
}

export const HOP_R = 4;
const CELL = 256;

/** A bucket grid over boxes: which boxes a rectangle meets. */
export class BoxIndex {
  private cells = new Map<string, Box[]>();
  constructor(boxes: Box[]) {
    for (const b of boxes) {
      const [i0, j0, i1, j1] = this.span(b);
      if ((i1 - i0 + 1) * (j1 - j0 + 1) > 4096) continue; // absurd sizes: never an obstacle
      for (let i = i0; i <= i1; i++)
        for (let j = j0; j <= j1; j++) {
          const k = `${i},${j}`;
          const l = this.cells.get(k);
          if (l) l.push(b);
          else this.cells.set(k, [b]);
        }
    }
  }
  private span(r: Rect): [number, number, number, number] {
    return [Math.floor(r.x / CELL), Math.floor(r.y / CELL), Math.floor((r.x + r.w) / CELL), Math.floor((r.y + r.h) / CELL)];
  }
  query(r: Rect): Box[] {
    const [i0, j0, i1, j1] = this.span(r);
    const seen = new Set<Box>();
    if ((i1 - i0 + 1) * (j1 - j0 + 1) > 4096) return [];
    for (let i = i0; i <= i1; i++)
      for (let j = j0; j <= j1; j++)
        for (const b of this.cells.get(`${i},${j}`) ?? [])
          if (!seen.has(b) && b.x < r.x + r.w && b.x + b.w > r.x && b.y < r.y + r.h && b.y + b.h > r.y) seen.add(b);
    return [...seen];
  }
}

function bboxOf(pts: Pt[], grow = 0): Rect {
  let x0 = Infinity;
  let y0 = Infinity;
  let x1 = -Infinity;
  let y1 = -Infinity;
  for (const [x, y] of pts) {
    x0 = Math.min(x0, x);
    y0 = Math.min(y0, y);
    x1 = Math.max(x1, x);
    y1 = Math.max(y1, y);
  }
  return { x: x0 - grow, y: y0 - grow, w: x1 - x0 + 2 * grow, h: y1 - y0 + 2 * grow };
}

function union(a: Rect, b: Rect): Rect {
  const x = Math.min(a.x, b.x);
  const y = Math.min(a.y, b.y);
  return { x, y, w: Math.max(a.x + a.w, b.x + b.w) - x, h: Math.max(a.y + a.h, b.y + b.h) - y };
}

const meets = (a: Rect, b: Rect) => a.x < b.x + b.w && a.x + a.w > b.x && a.y < b.y + b.h && a.y + a.h > b.y;

interface Cached {
  ends: string;
  region: Rect;
  points: Pt[];
  how: Route['how'];
}

/** The routes of one level's wires, kept between updates (see the module's comment). */
export class Wiring {
  private cache = new Map<string, Cached>();
  private boxes = new Map<string, Box>();
  private last = new Map<string, Route>();
  opts: RouterOptions;
  /** Wires routed anew by the last update (the others reused their route). */
  rerouted = 0;
  constructor(opts: Partial<RouterOptions> = {}) {
    this.opts = { ...DEFAULTS, ...opts };
  }

  private routeOne(w: WireEnds, index: BoxIndex): Cached {
    const o = this.opts;
    // the blocks near the wire; then those along the route found, until none is new
    let region = bboxOf([w.from, w.to], 3 * o.stub + o.margin);
    let near = index.query(region);
    let res = routeWire(w.from, w.to, near, o);
    for (let round = 0; round < 3; round++) {
      const grown = union(region, bboxOf(res.points, o.pad + 1));
      const more = index.query(grown);
      region = grown;
      if (more.length === near.length) break;
      near = more;
      res = routeWire(w.from, w.to, near, o);
    }
    this.rerouted++;
    return { ends: `${w.from[0]},${w.from[1]}>${w.to[0]},${w.to[1]}`, region, points: res.points, how: res.how };
  }

  /** Routes for `wires` among `boxes` (every block and group drawn at the level). A wire
   * whose ends did not move keeps its route unless a block that appeared, went or moved
   * (where it was or where it is) meets the region its route was found in. */
  update(boxes: Box[], wires: WireEnds[]): Map<string, Route> {
    this.rerouted = 0;
    const changed: Rect[] = [];
    const now = new Map<string, Box>();
    for (const b of boxes) {
      now.set(b.id, b);
      const was = this.boxes.get(b.id);
      if (!was || was.x !== b.x || was.y !== b.y || was.w !== b.w || was.h !== b.h) {
        changed.push(b);
        if (was) changed.push(was);
      }
    }
    for (const [id, b] of this.boxes) if (!now.has(id)) changed.push(b);
    this.boxes = now;
    let index: BoxIndex | null = null;
    const raw: { w: WireEnds; points: Pt[]; how: Route['how'] }[] = [];
    const live = new Set<string>();
    for (const w of wires) {
      live.add(w.id);
      let c = this.cache.get(w.id);
      const ends = `${w.from[0]},${w.from[1]}>${w.to[0]},${w.to[1]}`;
      if (!c || c.ends !== ends || changed.some((r) => meets(r, c!.region))) {
        index ??= new BoxIndex(boxes);
        c = this.routeOne(w, index);
        this.cache.set(w.id, c);
      }
      raw.push({ w, points: c.points.map((p) => [p[0], p[1]] as Pt), how: c.how });
    }
    for (const k of [...this.cache.keys()]) if (!live.has(k)) this.cache.delete(k);
    nudge(raw, this.opts.pad);
    const hops = crossings(raw);
    const dots = junctions(raw);
    const out = new Map<string, Route>();
    for (const r of raw) {
      const h = hops.get(r.w.id) ?? [];
      const dd = dots.get(r.w.id) ?? [];
      const d = pathOf(r.points, h);
      // the same route object when nothing about it changed (what is drawn from it is kept)
      const was = this.last.get(r.w.id);
      if (was && was.d === d && was.net === r.w.net && was.how === r.how && sameDots(was.dots, dd)) out.set(r.w.id, was);
      else out.set(r.w.id, { id: r.w.id, net: r.w.net, points: r.points, hops: h, dots: dd, how: r.how, d });
    }
    this.last = out;
    return out;
  }
}

function sameDots(a: Pt[], b: Pt[]): boolean {
  return a.length === b.length && a.every((p, i) => p[0] === b[i][0] && p[1] === b[i][1]);
}

// ------------------------------------------------------------------ nudging

interface Seg {
  r: number; // route index
  i: number; // segment index (points i, i+1)
  vertical: boolean;
  c: number; // the coordinate it runs on (x of a vertical one)
  lo: number;
  hi: number;
  net: string;
}

/** Spread apart collinear, overlapping runs of different nets (interior segments only: the
 * runs out of and into ports stay on their port's line). */
export function nudge(raw: { w: WireEnds; points: Pt[] }[], pad: number) {
  for (const vertical of [true, false]) {
    const groups = new Map<number, Seg[]>();
    raw.forEach((r, ri) => {
      const p = r.points;
      for (let i = 1; i + 2 < p.length; i++) {
        const a = p[i];
        const b = p[i + 1];
        const isV = a[0] === b[0] && a[1] !== b[1];
        const isH = a[1] === b[1] && a[0] !== b[0];
        if (vertical ? !isV : !isH) continue;
        const c = vertical ? a[0] : a[1];
        const s: Seg = {
          r: ri,
          i,
          vertical,
          c,
          lo: vertical ? Math.min(a[1], b[1]) : Math.min(a[0], b[0]),
          hi: vertical ? Math.max(a[1], b[1]) : Math.max(a[0], b[0]),
          net: r.w.net,
        };
        const k = Math.round(c);
        const l = groups.get(k);
        if (l) l.push(s);
        else groups.set(k, [s]);
      }
    });
    for (const segs of groups.values()) {
      if (segs.length < 2) continue;
      segs.sort((a, b) => a.lo - b.lo);
      // clusters of overlapping ranges
      let cluster: Seg[] = [];
      let end = -Infinity;
      const flush = () => {
        const nets = [...new Set(cluster.map((s) => s.net))].sort();
        if (nets.length > 1) {
          const step = Math.min(6, (2 * (pad - 2)) / nets.length);
          for (const s of cluster) {
            const lane = nets.indexOf(s.net);
            const off = Math.round((lane - (nets.length - 1) / 2) * step);
            if (!off) continue;
            const p = raw[s.r].points;
            if (vertical) {
              p[s.i] = [p[s.i][0] + off, p[s.i][1]];
              p[s.i + 1] = [p[s.i + 1][0] + off, p[s.i + 1][1]];
            } else {
              p[s.i] = [p[s.i][0], p[s.i][1] + off];
              p[s.i + 1] = [p[s.i + 1][0], p[s.i + 1][1] + off];
            }
          }
        }
        cluster = [];
      };
      for (const s of segs) {
        if (cluster.length && s.lo >= end) flush();
        cluster.push(s);
        end = Math.max(end, s.hi);
      }
      flush();
    }
  }
}

// ------------------------------------------------------------------ crossings

/** Hops: a horizontal run crossing a vertical run of another net hops over it. */
export function crossings(raw: { w: WireEnds; points: Pt[] }[]): Map<string, Hop[]> {
  type V = { x: number; lo: number; hi: number; net: string };
  const vs: V[] = [];
  for (const r of raw) {
    const p = r.points;
    for (let i = 0; i + 1 < p.length; i++)
      if (p[i][0] === p[i + 1][0] && p[i][1] !== p[i + 1][1])
        vs.push({ x: p[i][0], lo: Math.min(p[i][1], p[i + 1][1]), hi: Math.max(p[i][1], p[i + 1][1]), net: r.w.net });
  }
  vs.sort((a, b) => a.x - b.x);
  const xs = vs.map((v) => v.x);
  const first = (x: number) => {
    let lo = 0;
    let hi = xs.length;
    while (lo < hi) {
      const m = (lo + hi) >> 1;
      if (xs[m] < x) lo = m + 1;
      else hi = m;
    }
    return lo;
  };
  const m = 2 * HOP_R; // not at a bend or an end
  const out = new Map<string, Hop[]>();
  for (const r of raw) {
    const p = r.points;
    const hops: Hop[] = [];
    for (let i = 0; i + 1 < p.length; i++) {
      if (p[i][1] !== p[i + 1][1] || p[i][0] === p[i + 1][0]) continue;
      const y = p[i][1];
      const lo = Math.min(p[i][0], p[i + 1][0]) + m;
      const hi = Math.max(p[i][0], p[i + 1][0]) - m;
      for (let k = first(lo); k < vs.length && vs[k].x <= hi; k++) {
        const v = vs[k];
        if (v.net === r.w.net || !(y > v.lo + 1 && y < v.hi - 1)) continue;
        if (hops.some((h) => h.y === y && Math.abs(h.x - v.x) < 2 * HOP_R + 1)) continue; // one hop for close wires
        hops.push({ x: v.x, y });
      }
    }
    if (hops.length) out.set(r.w.id, hops);
  }
  return out;
}

// ------------------------------------------------------------------ junctions

/** Where two routes from one point part (they start at the same port). */
export function partingPoint(a: Pt[], b: Pt[]): Pt | null {
  let i = 0;
  let j = 0;
  let cur: Pt = a[0];
  if (a[0][0] !== b[0][0] || a[0][1] !== b[0][1]) return null;
  while (i + 1 < a.length && j + 1 < b.length) {
    const da = [Math.sign(a[i + 1][0] - cur[0]), Math.sign(a[i + 1][1] - cur[1])];
    const db = [Math.sign(b[j + 1][0] - cur[0]), Math.sign(b[j + 1][1] - cur[1])];
    if (da[0] !== db[0] || da[1] !== db[1]) return cur;
    const la = Math.abs(a[i + 1][0] - cur[0]) + Math.abs(a[i + 1][1] - cur[1]);
    const lb = Math.abs(b[j + 1][0] - cur[0]) + Math.abs(b[j + 1][1] - cur[1]);
    if (la === lb) {
      cur = a[i + 1];
      i++;
      j++;
    } else if (la < lb) {
      cur = a[i + 1];
      i++;
    } else {
      cur = b[j + 1];
      j++;
    }
  }
  return cur;
}

/** Junction dots of each net with several wires, drawn by the net's first wire. */
export function junctions(raw: { w: WireEnds; points: Pt[] }[]): Map<string, Pt[]> {
  const nets = new Map<string, { w: WireEnds; points: Pt[] }[]>();
  for (const r of raw) {
    const l = nets.get(r.w.net);
    if (l) l.push(r);
    else nets.set(r.w.net, [r]);
  }
  const out = new Map<string, Pt[]>();
  for (const rs of nets.values()) {
    if (rs.length < 2) continue;
    const dots: Pt[] = [];
    for (let a = 0; a < rs.length; a++)
      for (let b = a + 1; b < rs.length; b++) {
        const p = partingPoint(rs[a].points, rs[b].points);
        if (p && !dots.some((d) => d[0] === p[0] && d[1] === p[1])) dots.push(p);
      }
    out.set(rs[0].w.id, dots);
  }
  return out;
}

// ------------------------------------------------------------------ drawing

/** The SVG path of a route: straight runs, small rounded bends, and a hop (a half circle
 * over the other wire) at each crossing of a horizontal run. */
export function pathOf(points: Pt[], hops: Hop[] = [], radius = 5): string {
  if (!points.length) return '';
  const f = (v: number) => (Math.round(v * 10) / 10).toString();
  let d = `M${f(points[0][0])},${f(points[0][1])}`;
  for (let i = 1; i < points.length; i++) {
    const a = points[i - 1];
    const b = points[i];
    const c = points[i + 1];
    // hops on this run, in the direction of travel
    if (a[1] === b[1] && a[0] !== b[0]) {
      const dir = Math.sign(b[0] - a[0]);
      const on = hops.filter((h) => h.y === a[1] && (h.x - a[0]) * dir > 0 && (b[0] - h.x) * dir > 0).sort((p, q) => (p.x - q.x) * dir);
      for (const h of on) {
        d += `L${f(h.x - dir * HOP_R)},${f(h.y)}A${HOP_R},${HOP_R} 0 0 ${dir > 0 ? 1 : 0} ${f(h.x + dir * HOP_R)},${f(h.y)}`;
      }
    }
    if (!c) {
      d += `L${f(b[0])},${f(b[1])}`;
      break;
    }
    // a rounded bend at b (no wider than half of either run)
    const l1 = Math.abs(b[0] - a[0]) + Math.abs(b[1] - a[1]);
    const l2 = Math.abs(c[0] - b[0]) + Math.abs(c[1] - b[1]);
    const r = Math.min(radius, l1 / 2, l2 / 2);
    if (r < 0.5) {
      d += `L${f(b[0])},${f(b[1])}`;
      continue;
    }
    const ux = Math.sign(b[0] - a[0]);
    const uy = Math.sign(b[1] - a[1]);
    const vx = Math.sign(c[0] - b[0]);
    const vy = Math.sign(c[1] - b[1]);
    d += `L${f(b[0] - ux * r)},${f(b[1] - uy * r)}Q${f(b[0])},${f(b[1])} ${f(b[0] + vx * r)},${f(b[1] + vy * r)}`;
  }
  return d;
}

/** Whether any run of the route passes through a block other than its own two (for tests and
 * for the benchmark's counts), given the blocks' unpadded rectangles. */
export function hitsForeign(route: Pt[], boxes: Box[], own: string[]): string[] {
  const hit: string[] = [];
  for (const b of boxes) {
    if (own.includes(b.id)) continue;
    for (let i = 0; i + 1 < route.length; i++)
      if (segmentHits(route[i], route[i + 1], b)) {
        hit.push(b.id);
        break;
      }
  }
  return hit;
}

export { padRect };
