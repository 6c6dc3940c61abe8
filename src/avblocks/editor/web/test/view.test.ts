// Fitting the view: into what the canvas shows, never below a readable zoom.
import { describe, expect, it } from 'vitest';
import { fitViewport, READABLE_ZOOM, visibleArea } from '../src/hooks/useViewMoves';
import { fromJson, toJson } from '../src/transport';

describe('fit view', () => {
  it('keeps clear of the minimap corner, the zoom buttons and the breadcrumb', () => {
    const a = visibleArea(870, 780);
    // a wide canvas: the strip above the minimap (216 x 166) is the larger one
    expect(a).toEqual({ x: 48, y: 44, w: 822, h: 570 });
    // a plot panel in the corner, larger than the minimap, widens what is kept clear
    const b = visibleArea(870, 780, [{ w: 480, h: 500 }]);
    expect(b.w * b.h).toBeLessThan(a.w * a.h);
  });

  it('centres a diagram that fits, at most 1.2, inside the area', () => {
    const area = { x: 48, y: 44, w: 822, h: 570 };
    const v = fitViewport([0, 0, 400, 100], area);
    expect(v.clamped).toBe(false);
    expect(v.zoom).toBeCloseTo(1.2);
    // the bounds' corners land inside the area
    for (const [x, y] of [[0, 0], [400, 100]]) {
      const sx = x * v.zoom + v.x;
      const sy = y * v.zoom + v.y;
      expect(sx).toBeGreaterThanOrEqual(area.x);
      expect(sx).toBeLessThanOrEqual(area.x + area.w);
      expect(sy).toBeGreaterThanOrEqual(area.y);
      expect(sy).toBeLessThanOrEqual(area.y + area.h);
    }
    const w = fitViewport([100, 50, 800, 450], area);
    expect(w.clamped).toBe(false);
    expect(w.zoom).toBeCloseTo((822 - 48) / 700);
  });

  it('never goes below the readable zoom: a large diagram is shown from its top left', () => {
    const area = { x: 48, y: 44, w: 822, h: 570 };
    const v = fitViewport([-200, 100, 5000, 3000], area);
    expect(v.clamped).toBe(true);
    expect(v.zoom).toBe(READABLE_ZOOM);
    expect(READABLE_ZOOM * 12).toBeCloseTo(10); // a block's name (12 px) at 10 px
    expect(-200 * v.zoom + v.x).toBeCloseTo(area.x + 24);
    expect(100 * v.zoom + v.y).toBeCloseTo(area.y + 24);
  });
});

describe('answers', () => {
  it('read the numbers Python writes for NaN and the infinities, outside strings', () => {
    expect(fromJson('{"a": 1}')).toEqual({ a: 1 });
    expect(fromJson('{"gain": NaN, "v": [Infinity, -Infinity], "s": "NaN Infinity"}')).toEqual({ gain: NaN, v: [Infinity, -Infinity], s: 'NaN Infinity' });
    expect(() => fromJson('{oops')).toThrow();
  });
});

describe('requests', () => {
  it('write the numbers JSON cannot as Python reads them', () => {
    expect(toJson({ gain: NaN, v: [Infinity, -Infinity, 1], s: '\u0000NaN' })).toBe('{"gain":NaN,"v":[Infinity,-Infinity,1],"s":"\\u0000NaN"}');
  });
});
