// The wire router on hostile placements: it always returns an orthogonal path from port to
// port, never through a block that a route around exists for, and its work is bounded.
// Truth: each block's rectangle, checked segment by segment here (an independent
// segment-rectangle test below, not the router's own), and placements built so that a route
// exists.
import { describe, expect, it } from 'vitest';
import { DEFAULTS, routeWire } from '../src/router';
import type { Pt, Rect } from '../src/router';
import { crossings, junctions, partingPoint, pathOf, Wiring } from '../src/routes';
import type { Box, WireEnds } from '../src/routes';

// a tiny seeded generator (mulberry32)
function rng(seed: number) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

/** Does the axis-parallel segment a-b pass through the open rectangle r? (written apart from
 * the router: sample points along the segment) */
function crosses(a: Pt, b: Pt, r: Rect): boolean {
  if (Math.max(a[0], b[0]) < r.x || Math.min(a[0], b[0]) > r.x + r.w || Math.max(a[1], b[1]) < r.y || Math.min(a[1], b[1]) > r.y + r.h) return false;
  const n = Math.max(2, Math.ceil((Math.abs(b[0] - a[0]) + Math.abs(b[1] - a[1])) / 2));
  for (let k = 0; k <= n; k++) {
    const x = a[0] + ((b[0] - a[0]) * k) / n;
    const y = a[1] + ((b[1] - a[1]) * k) / n;
    if (x > r.x + 0.5 && x < r.x + r.w - 0.5 && y > r.y + 0.5 && y < r.y + r.h - 0.5) return true;
  }
  return false;
}

function orthogonal(p: Pt[]): boolean {
  return p.every((q, i) => i === 0 || q[0] === p[i - 1][0] || q[1] === p[i - 1][1]);
}

/** Output port of a block (right side) and input port (left side), row k. */
const outPort = (b: Rect, k = 0): Pt => [b.x + b.w + 7, b.y + 45 + 22 * k];
const inPort = (b: Rect, k = 0): Pt => [b.x - 7, b.y + 45 + 22 * k];

function check(s: Pt, t: Pt, blocks: Rect[], own: Rect[]) {
  const r = routeWire(s, t, blocks);
  const p = r.points;
  expect(p.length).toBeGreaterThanOrEqual(2);
  expect(p[0]).toEqual(s);
  expect(p[p.length - 1]).toEqual(t);
  expect(orthogonal(p)).toBe(true);
  // it leaves the output heading east and enters the input heading east
  expect(p[1][1]).toBe(s[1]);
  expect(p[1][0]).toBeGreaterThan(s[0]);
  expect(p[p.length - 2][1]).toBe(t[1]);
  expect(p[p.length - 2][0]).toBeLessThan(t[0]);
  const foreign = blocks.filter((b) => !own.includes(b));
  const under: string[] = [];
  for (let i = 0; i + 1 < p.length; i++) for (const b of foreign) if (crosses(p[i], p[i + 1], b)) under.push(`segment ${i} of ${JSON.stringify(p)} under ${JSON.stringify(b)}`);
  // its own blocks: only the stubs touch them
  for (let i = 1; i + 2 < p.length; i++) for (const b of own) if (crosses(p[i], p[i + 1], b)) under.push(`segment ${i} under its own block ${JSON.stringify(b)}`);
  expect(under).toEqual([]);
  return r;
}

describe('routeWire', () => {
  it('takes the straight run when nothing is in the way', () => {
    const a = { x: 0, y: 0, w: 210, h: 80 };
    const b = { x: 400, y: 0, w: 210, h: 80 };
    const r = check(outPort(a), inPort(b), [a, b], [a, b]);
    expect(r.how).toBe('straight');
    expect(r.points).toEqual([outPort(a), inPort(b)]);
  });

  it('goes around a block in the way', () => {
    const a = { x: 0, y: 0, w: 210, h: 80 };
    const mid = { x: 300, y: -20, w: 200, h: 140 };
    const b = { x: 600, y: 0, w: 210, h: 80 };
    const r = check(outPort(a), inPort(b), [a, mid, b], [a, b]);
    expect(r.how).toBe('grid');
    // and keeps its clearance from it
    const padded = { x: mid.x - DEFAULTS.pad + 1, y: mid.y - DEFAULTS.pad + 1, w: mid.w + 2 * DEFAULTS.pad - 2, h: mid.h + 2 * DEFAULTS.pad - 2 };
    for (let i = 0; i + 1 < r.points.length; i++) expect(crosses(r.points[i], r.points[i + 1], padded)).toBe(false);
  });

  it('draws a feedback wire below the row it returns past', () => {
    // fleet -> drive on one row; drive.cmd back into fleet.cmd (the waypoints case)
    const fleet = { x: 0, y: 0, w: 210, h: 80 };
    const drive = { x: 300, y: 0, w: 210, h: 80 };
    const r = check(outPort(drive), inPort(fleet), [fleet, drive], [fleet, drive]);
    const runs = r.points.slice(1, -1);
    const lowest = Math.max(...runs.map((p) => p[1]));
    expect(lowest).toBeGreaterThan(80); // below both blocks
    expect(Math.min(...runs.map((p) => p[1]))).toBeGreaterThanOrEqual(outPort(drive)[1]); // never above
  });

  it('goes round a block between the ends of a feedback wire (formation: under the supervisor)', () => {
    const fleet = { x: 0, y: 100, w: 210, h: 80 };
    const sup = { x: 300, y: 60, w: 240, h: 200 };
    const lf = { x: 620, y: 100, w: 210, h: 80 };
    // fleet.pose -> lf.pose would run straight under the supervisor
    check(outPort(fleet), inPort(lf), [fleet, sup, lf], [fleet, lf]);
    // and lf back to fleet, past the supervisor
    check(outPort(lf), inPort(fleet, 1), [fleet, sup, lf], [fleet, lf]);
  });

  it('routes a block wired to itself around itself', () => {
    const a = { x: 0, y: 0, w: 210, h: 80 };
    check(outPort(a), inPort(a), [a], [a]);
  });

  it('returns a path for ports facing away, on top of each other, at zero distance', () => {
    const a = { x: 0, y: 0, w: 210, h: 80 };
    const b = { x: 0, y: 200, w: 210, h: 80 }; // right below: the input faces away
    check(outPort(a), inPort(b), [a, b], [a, b]);
    check(outPort(b), inPort(a), [a, b], [a, b]);
    for (const [s, t] of [
      [[100, 100], [100, 100]],
      [[0, 0], [1, 0]],
      [[0, 0], [0, 1]],
    ] as [Pt, Pt][]) {
      const r = routeWire(s, t, []);
      expect(r.points[0]).toEqual(s);
      expect(r.points[r.points.length - 1]).toEqual(t);
      expect(orthogonal(r.points)).toBe(true);
    }
  });

  it('returns a path when blocks overlap or sit inside each other (no route may exist)', () => {
    const big = { x: 0, y: 0, w: 800, h: 600 };
    const a = { x: 100, y: 100, w: 210, h: 80 }; // inside big
    const b = { x: 450, y: 300, w: 210, h: 80 }; // inside big
    const c = { x: 150, y: 120, w: 210, h: 80 }; // overlaps a
    for (const [s, t] of [
      [outPort(a), inPort(b)],
      [outPort(b), inPort(a)],
      [outPort(c), inPort(a)],
      [outPort(a), inPort(c)],
    ] as [Pt, Pt][]) {
      const r = routeWire(s, t, [big, a, b, c]);
      expect(r.points[0]).toEqual(s);
      expect(r.points[r.points.length - 1]).toEqual(t);
      expect(orthogonal(r.points)).toBe(true);
    }
  });

  it('finds a route on seeded random placements (no overlap: one always exists)', () => {
    let fallbacks = 0;
    for (let seed = 1; seed <= 40; seed++) {
      const rand = rng(seed);
      // blocks on a jittered grid, never overlapping
      const blocks: Rect[] = [];
      for (let i = 0; i < 5; i++)
        for (let j = 0; j < 4; j++) if (rand() < 0.7) blocks.push({ x: i * 330 + rand() * 60, y: j * 190 + rand() * 50, w: 200 + rand() * 40, h: 60 + rand() * 40 });
      for (let k = 0; k < 12; k++) {
        const a = blocks[Math.floor(rand() * blocks.length)];
        const b = blocks[Math.floor(rand() * blocks.length)];
        const r = check(outPort(a), inPort(b), blocks, a === b ? [a] : [a, b]);
        if (r.how === 'fallback') fallbacks++;
      }
    }
    expect(fallbacks).toBe(0);
  });

  it('is bounded on a huge diagram: a path comes back from across 3000 blocks', () => {
    const rand = rng(7);
    const blocks: Rect[] = [];
    for (let i = 0; i < 60; i++) for (let j = 0; j < 50; j++) blocks.push({ x: i * 300 + rand() * 40, y: j * 150 + rand() * 30, w: 210, h: 80 });
    const s = outPort(blocks[0]);
    const t = inPort(blocks[blocks.length - 1]);
    const r = routeWire(s, t, blocks);
    expect(r.points[0]).toEqual(s);
    expect(r.points[r.points.length - 1]).toEqual(t);
    expect(orthogonal(r.points)).toBe(true);
    // a wire to a near neighbour in the same huge diagram is routed properly
    const near = check(outPort(blocks[61]), inPort(blocks[62]), blocks.slice(0, 200), [blocks[61], blocks[62]]);
    expect(near.how).not.toBe('fallback');
  });
});

describe('Wiring', () => {
  const box = (id: string, x: number, y: number, w = 210, h = 80): Box => ({ id, x, y, w, h });
  const wire = (id: string, net: string, a: Box, b: Box, ka = 0, kb = 0): WireEnds => ({ id, net, source: a.id, target: b.id, from: outPort(a, ka), to: inPort(b, kb) });

  it('reroutes only the wires near a moved block', () => {
    const bs = [box('a', 0, 0), box('b', 500, 0), box('c', 0, 2000), box('d', 400, 2000)];
    const ws = [wire('ab', 'a', bs[0], bs[1]), wire('cd', 'c', bs[2], bs[3])];
    const wr = new Wiring();
    wr.update(bs, ws);
    expect(wr.rerouted).toBe(2);
    wr.update(bs, ws);
    expect(wr.rerouted).toBe(0);
    const moved = [...bs.slice(0, 3), box('d', 420, 2010)];
    const ws2 = [ws[0], wire('cd', 'c', moved[2], moved[3])];
    wr.update(moved, ws2);
    expect(wr.rerouted).toBe(1);
    // a block dropped in the way of ab reroutes ab around it (and nothing else)
    const inWay = [...moved, box('x', 260, -30, 120, 140)];
    const r = wr.update(inWay, ws2);
    expect(wr.rerouted).toBe(1);
    for (let i = 0; i + 1 < r.get('ab')!.points.length; i++) expect(crosses(r.get('ab')!.points[i], r.get('ab')!.points[i + 1], inWay[4])).toBe(false);
  });

  it('spreads apart runs of different nets on one line, keeps a net together with a junction dot', () => {
    // two sources on the left, two targets on the right, one block between: both wires would
    // take the same channel
    const a = box('a', 0, 0);
    const a2 = box('a2', 0, 100);
    const mid = box('m', 300, -100, 100, 400);
    const b = box('b', 600, 0);
    const b2 = box('b2', 600, 100);
    const ws = [wire('w1', 'a', a, b), wire('w2', 'a2', a2, b2), wire('w3', 'a', a, b2, 0, 1)];
    const r = new Wiring().update([a, a2, mid, b, b2], ws);
    const segs = (id: string) => {
      const p = r.get(id)!.points;
      return p.slice(1, -2).map((q, i) => [q, p[i + 2]] as [Pt, Pt]);
    };
    // no interior run of w1 lies on a run of w2 (different nets)
    for (const [p, q] of segs('w1'))
      for (const [u, v] of segs('w2')) {
        const sameV = p[0] === q[0] && u[0] === v[0] && p[0] === u[0] && Math.max(p[1], q[1]) > Math.min(u[1], v[1]) && Math.max(u[1], v[1]) > Math.min(p[1], q[1]);
        const sameH = p[1] === q[1] && u[1] === v[1] && p[1] === u[1] && Math.max(p[0], q[0]) > Math.min(u[0], v[0]) && Math.max(u[0], v[0]) > Math.min(p[0], q[0]);
        expect(sameV || sameH).toBe(false);
      }
    // net a (w1, w3) has one junction dot, where its wires part; it lies on both of them
    const dots = [...r.values()].flatMap((x) => x.dots);
    expect(dots.length).toBe(1);
    const onPath = (p: Pt[], d: Pt) => p.some((q, i) => i > 0 && Math.min(q[0], p[i - 1][0]) <= d[0] && d[0] <= Math.max(q[0], p[i - 1][0]) && Math.min(q[1], p[i - 1][1]) <= d[1] && d[1] <= Math.max(q[1], p[i - 1][1]));
    expect(onPath(r.get('w1')!.points, dots[0])).toBe(true);
    expect(onPath(r.get('w3')!.points, dots[0])).toBe(true);
  });

  it('hops where a horizontal run crosses a vertical run of another net', () => {
    const raw = [
      { w: { id: 'h', net: 'n1', source: '', target: '', from: [0, 50], to: [200, 50] } as WireEnds, points: [[0, 50], [200, 50]] as Pt[] },
      { w: { id: 'v', net: 'n2', source: '', target: '', from: [80, 0], to: [120, 100] } as WireEnds, points: [[80, 0], [100, 0], [100, 100], [120, 100]] as Pt[] },
      { w: { id: 'same', net: 'n1', source: '', target: '', from: [0, 50], to: [150, 120] } as WireEnds, points: [[0, 50], [150, 50], [150, 120]] as Pt[] },
    ];
    const hops = crossings(raw);
    expect(hops.get('h')).toEqual([{ x: 100, y: 50 }]); // crosses v, not its own net's run at 150
    expect(hops.get('same')).toEqual([{ x: 100, y: 50 }]);
    expect(hops.get('v')).toBeUndefined();
    expect(pathOf(raw[0].points, hops.get('h'))).toBe('M0,50L96,50A4,4 0 0 1 104,50L200,50');
    expect(junctions(raw).get('h')).toEqual([[150, 50]]);
    expect(partingPoint([[0, 0], [10, 0], [10, 10]], [[0, 0], [10, 0], [20, 0]])).toEqual([10, 0]);
  });

  it('routes the 500-block benchmark diagram in bounded work, none under a foreign block', () => {
    // teams of two blocks wired both ways on a grid (benchmarks/editor.py's document)
    const bs: Box[] = [];
    const ws: WireEnds[] = [];
    for (let k = 0; k < 250; k++) {
      const x = (k % 10) * 620;
      const y = Math.floor(k / 10) * 160;
      const f = box(`f${k}`, x, y, 210, 66);
      const d = box(`d${k}`, x + 300, y, 210, 132);
      bs.push(f, d);
      ws.push(wire(`fd${k}`, `f${k}`, f, d), wire(`df${k}`, `d${k}`, d, f));
    }
    const r = new Wiring().update(bs, ws);
    expect(r.size).toBe(500);
    const under: string[] = [];
    for (const w of ws) {
      const p = r.get(w.id)!.points;
      for (const b of bs) {
        if (b.id === w.source || b.id === w.target) continue;
        for (let i = 0; i + 1 < p.length; i++) if (crosses(p[i], p[i + 1], b)) under.push(`${w.id} under ${b.id}`);
      }
    }
    expect(under).toEqual([]);
    expect([...r.values()].filter((x) => x.how === 'fallback')).toEqual([]);
  });
});
