// Orthogonal wire routing around blocks (pure: no React, no DOM; tested with Vitest).
//
// A wire leaves an output port to the right and enters an input port from the left. Its
// route is found on a sparse grid (an orthogonal visibility graph): the lines through the
// edges of the padded block rectangles near the wire, the channels midway between them,
// the two port stubs and a frame around them; A* over (grid point, heading) with a cost
// for length and one for each bend finds the shortest route with few bends that enters
// no padded block. A wire that runs backwards (a feedback wire, target left of source)
// pays more for running above its ports, so it is drawn below the blocks it returns past,
// as Simulink draws it.
//
// The work is bounded: at most MAX_OBSTACLES blocks near a wire take part, the grid has at
// most MAX_GRID points and A* expands at most MAX_EXPANSIONS states; past a bound, or when
// no route exists (a port inside another block), a plain route with at most five segments
// is returned. Every call returns a path.

export type Pt = [number, number];

export interface Rect {
  x: number;
  y: number;
  w: number;
  h: number;
}

export interface RouterOptions {
  /** Clearance kept around blocks [px]. */
  pad: number;
  /** Straight run out of an output / into an input before the first bend [px]. */
  stub: number;
  /** Cost of one bend, in pixels of length. */
  bend: number;
  /** Extra cost per pixel of a feedback wire's horizontal run above its ports (fraction). */
  above: number;
  /** Frame around the wire's neighbourhood in which it may go round [px]. */
  margin: number;
}

export const DEFAULTS: RouterOptions = { pad: 12, stub: 18, bend: 24, above: 0.35, margin: 60 };

export const MAX_OBSTACLES = 80;
export const MAX_GRID = 40_000;
export const MAX_EXPANSIONS = 60_000;

export interface RouteResult {
  points: Pt[];
  /** How it was found: 'grid' (A* around the blocks), 'straight' (nothing in the way),
   * 'fallback' (a bound was reached or no route exists: it may cross blocks). */
  how: 'grid' | 'straight' | 'fallback';
}

const inside = (r: Rect, x: number, y: number) => x > r.x && x < r.x + r.w && y > r.y && y < r.y + r.h;

export function padRect(r: Rect, p: number): Rect {
  return { x: r.x - p, y: r.y - p, w: r.w + 2 * p, h: r.h + 2 * p };
}

/** Whether the axis-parallel segment a-b passes through the inside of r (its border is free). */
export function segmentHits(a: Pt, b: Pt, r: Rect): boolean {
  if (a[1] === b[1]) {
    const y = a[1];
    if (!(y > r.y && y < r.y + r.h)) return false;
    const lo = Math.min(a[0], b[0]);
    const hi = Math.max(a[0], b[0]);
    return hi > r.x && lo < r.x + r.w;
  }
  const x = a[0];
  if (!(x > r.x && x < r.x + r.w)) return false;
  const lo = Math.min(a[1], b[1]);
  const hi = Math.max(a[1], b[1]);
  return hi > r.y && lo < r.y + r.h;
}

/** The same path without repeated points and with collinear runs merged. */
export function simplify(pts: Pt[]): Pt[] {
  const out: Pt[] = [];
  for (const p of pts) {
    const q = out[out.length - 1];
    if (q && q[0] === p[0] && q[1] === p[1]) continue;
    if (out.length >= 2) {
      const o = out[out.length - 2];
      if ((o[0] === q[0] && q[0] === p[0]) || (o[1] === q[1] && q[1] === p[1])) {
        out[out.length - 1] = p;
        continue;
      }
    }
    out.push(p);
  }
  return out;
}

/** A plain route (no search): out of the source, across, into the target. */
export function plainRoute(s: Pt, t: Pt, o: RouterOptions = DEFAULTS, below?: number): Pt[] {
  const sx = s[0] + o.stub;
  const tx = t[0] - o.stub;
  if (tx >= sx) {
    const mx = Math.round((sx + tx) / 2);
    return simplify([s, [mx, s[1]], [mx, t[1]], t]);
  }
  // backwards: down past both ports (or below what it returns past), across, up
  const y = below ?? Math.max(s[1], t[1]) + 3 * o.stub;
  return simplify([s, [sx, s[1]], [sx, y], [tx, y], [tx, t[1]], t]);
}

function uniqSorted(v: number[]): number[] {
  v.sort((a, b) => a - b);
  const out: number[] = [];
  for (const x of v) if (!out.length || x - out[out.length - 1] > 1e-6) out.push(x);
  return out;
}

/** Index of value v in sorted array a (exact, from the grid's own values). */
function indexOf(a: number[], v: number): number {
  let lo = 0;
  let hi = a.length - 1;
  while (lo <= hi) {
    const m = (lo + hi) >> 1;
    if (Math.abs(a[m] - v) <= 1e-6) return m;
    if (a[m] < v) lo = m + 1;
    else hi = m - 1;
  }
  return -1;
}

/** First index with a[i] >= v. */
function lowerBound(a: number[], v: number): number {
  let lo = 0;
  let hi = a.length;
  while (lo < hi) {
    const m = (lo + hi) >> 1;
    if (a[m] < v - 1e-6) lo = m + 1;
    else hi = m;
  }
  return lo;
}

// a binary heap of (priority, state)
class Heap {
  k: number[] = [];
  v: number[] = [];
  get size() {
    return this.k.length;
  }
  push(key: number, val: number) {
    const k = this.k;
    const v = this.v;
    let i = k.length;
    k.push(key);
    v.push(val);
    while (i > 0) {
      const p = (i - 1) >> 1;
      if (k[p] <= key) break;
      k[i] = k[p];
      v[i] = v[p];
      i = p;
    }
    k[i] = key;
    v[i] = val;
  }
  pop(): number {
    const k = this.k;
    const v = this.v;
    const top = v[0];
    const lk = k.pop()!;
    const lv = v.pop()!;
    const n = k.length;
    if (n) {
      let i = 0;
      for (;;) {
        let c = 2 * i + 1;
        if (c >= n) break;
        if (c + 1 < n && k[c + 1] < k[c]) c++;
        if (k[c] >= lk) break;
        k[i] = k[c];
        v[i] = v[c];
        i = c;
      }
      k[i] = lk;
      v[i] = lv;
    }
    return top;
  }
}

// headings: 0 east, 1 west, 2 south (down, +y), 3 north
const DX = [1, -1, 0, 0];
const DY = [0, 0, 1, -1];
const REVERSE = [1, 0, 3, 2];

/**
 * The route of one wire from output port `s` to input port `t` around `blocks` (their
 * unpadded rectangles: every block near the wire, its own two included).
 */
export function routeWire(s: Pt, t: Pt, blocks: Rect[], opts: Partial<RouterOptions> = {}): RouteResult {
  const o: RouterOptions = { ...DEFAULTS, ...opts };
  const S: Pt = [s[0] + o.stub, s[1]];
  const T: Pt = [t[0] - o.stub, t[1]];
  const backwards = T[0] < S[0];
  // blocks that hold a stub end (overlapping blocks, a port inside another block) cannot be
  // avoided: they take no part; the stubs themselves are not searched
  let obs = blocks.map((b) => padRect(b, o.pad)).filter((r) => !inside(r, S[0], S[1]) && !inside(r, T[0], T[1]));
  // nothing in the way of the plain route: take it
  const plain = plainRoute(s, t, o, backwards ? belowOf(obs, s, t, o) : undefined);
  if (clear(trimmed(plain, S, T), obs)) return { points: plain, how: 'straight' };
  if (obs.length > MAX_OBSTACLES) {
    // the nearest ones to the wire's box
    const cx = (S[0] + T[0]) / 2;
    const cy = (S[1] + T[1]) / 2;
    obs = obs
      .map((r) => ({ r, d: Math.abs(r.x + r.w / 2 - cx) + Math.abs(r.y + r.h / 2 - cy) }))
      .sort((a, b) => a.d - b.d)
      .slice(0, MAX_OBSTACLES)
      .map((x) => x.r);
  }
  const found = search(S, T, obs, o, backwards);
  if (!found) return { points: plain, how: 'fallback' };
  return { points: simplify([s, ...found, t]), how: 'grid' };
}

/** The first free line below a backwards wire's ports: no (padded) block between its ends
 * on it (for the plain route; the search takes over when its legs are not clear). */
function belowOf(obs: Rect[], s: Pt, t: Pt, o: RouterOptions): number {
  const lo = Math.min(s[0], t[0]) - o.stub;
  const hi = Math.max(s[0], t[0]) + o.stub;
  let y = Math.max(s[1], t[1]) + o.stub;
  for (let moved = true, n = 0; moved && n < obs.length + 1; n++) {
    moved = false;
    for (const r of obs)
      if (r.x < hi && r.x + r.w > lo && y > r.y - 1 && y < r.y + r.h + 1) {
        y = r.y + r.h + Math.min(o.stub, 2);
        moved = true;
      }
  }
  return y;
}

/** The path from the stub ends on (the stubs cross the wire's own blocks' clearance). */
function trimmed(pts: Pt[], S: Pt, T: Pt): Pt[] {
  const out = pts.slice();
  if (out.length >= 2 && out[1][1] === S[1] && out[1][0] >= S[0]) out[0] = S;
  const n = out.length;
  if (n >= 2 && out[n - 2][1] === T[1] && out[n - 2][0] <= T[0]) out[n - 1] = T;
  return out;
}

/** Whether segments i0..i1 of the path enter none of the rectangles. */
export function clear(pts: Pt[], obs: Rect[], i0 = 0, i1 = pts.length - 2): boolean {
  for (let i = Math.max(0, i0); i <= Math.min(i1, pts.length - 2); i++) for (const r of obs) if (segmentHits(pts[i], pts[i + 1], r)) return false;
  return true;
}

function search(S: Pt, T: Pt, obs: Rect[], o: RouterOptions, backwards: boolean): Pt[] | null {
  // the grid's lines: block edges, channels midway between them, the stub ends, a frame
  let minX = Math.min(S[0], T[0]);
  let maxX = Math.max(S[0], T[0]);
  let minY = Math.min(S[1], T[1]);
  let maxY = Math.max(S[1], T[1]);
  const ex: number[] = [];
  const ey: number[] = [];
  for (const r of obs) {
    ex.push(r.x, r.x + r.w);
    ey.push(r.y, r.y + r.h);
    minX = Math.min(minX, r.x);
    maxX = Math.max(maxX, r.x + r.w);
    minY = Math.min(minY, r.y);
    maxY = Math.max(maxY, r.y + r.h);
  }
  const edgesX = uniqSorted([...ex, S[0], T[0]]);
  const edgesY = uniqSorted([...ey, S[1], T[1]]);
  const xsv = [...edgesX, minX - o.margin, maxX + o.margin];
  const ysv = [...edgesY, minY - o.margin, maxY + o.margin];
  for (let i = 0; i + 1 < edgesX.length; i++) if (edgesX[i + 1] - edgesX[i] > 2 * o.pad) xsv.push(Math.round((edgesX[i] + edgesX[i + 1]) / 2));
  for (let i = 0; i + 1 < edgesY.length; i++) if (edgesY[i + 1] - edgesY[i] > 2 * o.pad) ysv.push(Math.round((edgesY[i] + edgesY[i + 1]) / 2));
  const xs = uniqSorted(xsv);
  const ys = uniqSorted(ysv);
  const nx = xs.length;
  const ny = ys.length;
  if (nx * ny > MAX_GRID) return null;
  const N = nx * ny;
  // blocked points and blocked moves (a move from point (i, j) one step east / south)
  const blocked = new Uint8Array(N);
  const eastBlocked = new Uint8Array(N);
  const southBlocked = new Uint8Array(N);
  for (const r of obs) {
    const i0 = lowerBound(xs, r.x);
    const i1 = lowerBound(xs, r.x + r.w); // xs[i1] == right edge
    const j0 = lowerBound(ys, r.y);
    const j1 = lowerBound(ys, r.y + r.h);
    for (let j = j0; j <= j1 && j < ny; j++) {
      const yIn = ys[j] > r.y && ys[j] < r.y + r.h;
      for (let i = i0; i <= i1 && i < nx; i++) {
        const xIn = xs[i] > r.x && xs[i] < r.x + r.w;
        const k = j * nx + i;
        if (xIn && yIn) blocked[k] = 1;
        // east move from i to i+1 on row j: inside when the row is inside and the span is
        if (yIn && i < i1) eastBlocked[k] = 1;
        if (xIn && j < j1) southBlocked[k] = 1;
      }
    }
  }
  const si = indexOf(xs, S[0]);
  const sj = indexOf(ys, S[1]);
  const ti = indexOf(xs, T[0]);
  const tj = indexOf(ys, T[1]);
  if (si < 0 || sj < 0 || ti < 0 || tj < 0) return null;
  const start = sj * nx + si;
  const goal = tj * nx + ti;
  const refY = Math.min(S[1], T[1]);
  const cost = new Float64Array(N * 4).fill(Infinity);
  const prev = new Int32Array(N * 4).fill(-1);
  const closed = new Uint8Array(N * 4);
  const heap = new Heap();
  const h = (k: number) => Math.abs(xs[k % nx] - T[0]) + Math.abs(ys[(k / nx) | 0] - T[1]);
  const s0 = start * 4 + 0; // leaving the source heading east
  cost[s0] = 0;
  heap.push(h(start), s0);
  let expanded = 0;
  let best = -1;
  while (heap.size) {
    const st = heap.pop();
    if (closed[st]) continue;
    closed[st] = 1;
    const k = st >> 2;
    const d = st & 3;
    if (k === goal) {
      best = st; // (a last turn into the target was paid for when it arrived)
      break;
    }
    if (++expanded > MAX_EXPANSIONS) return null;
    const i = k % nx;
    const j = (k / nx) | 0;
    for (let nd = 0; nd < 4; nd++) {
      if (nd === REVERSE[d]) continue;
      const ni = i + DX[nd];
      const nj = j + DY[nd];
      if (ni < 0 || nj < 0 || ni >= nx || nj >= ny) continue;
      const nk = nj * nx + ni;
      if (blocked[nk]) continue;
      if (nd === 0 && eastBlocked[k]) continue;
      if (nd === 1 && eastBlocked[nk]) continue;
      if (nd === 2 && southBlocked[k]) continue;
      if (nd === 3 && southBlocked[nk]) continue;
      if (nk === goal && nd === 1) continue; // arriving heading west would double back over the stub
      let len = Math.abs(xs[ni] - xs[i]) + Math.abs(ys[nj] - ys[j]);
      // a feedback wire's run above its ports costs more: it goes below
      if (backwards && nd < 2 && ys[j] < refY) len *= 1 + o.above;
      let c = cost[st] + len + (nd !== d ? o.bend : 0);
      if (nk === goal && nd !== 0) c += o.bend; // the last turn into the target
      const ns = nk * 4 + nd;
      if (c < cost[ns]) {
        cost[ns] = c;
        prev[ns] = st;
        heap.push(c + h(nk), ns);
      }
    }
  }
  if (best < 0) return null;
  const path: Pt[] = [];
  for (let st = best; st >= 0; st = prev[st]) {
    const k = st >> 2;
    path.push([xs[k % nx], ys[(k / nx) | 0]]);
  }
  path.reverse();
  return path;
}
