// Moves of the view: fitting what is drawn into the part of the canvas a person sees, never
// below a zoom where text stops being readable, and only the newest move when several are
// asked for in a row.

import { useCallback, useRef } from 'react';
import type { ReactFlowInstance } from '@xyflow/react';
import type { FlowEdge, FlowNode } from '../flow';

/** The smallest text drawn on a block (port names and shapes, wire labels) is 10.5-12 px at
 * zoom 1; fitting the view never goes below this zoom, where a block's name (12 px) is 10 px
 * on screen. A diagram larger than that is shown from its top left (scroll, or select
 * blocks and press F to fit them). */
export const READABLE_ZOOM = 10 / 12;
export const MAX_FIT_ZOOM = 1.2;
const PAD = 24;

/** What floats over the canvas, in pixels from its sides: the breadcrumb (top left), the zoom
 * buttons (bottom left), the minimap (bottom right, 200 x 150 + margins). */
const TOP = 44;
const LEFT_BUTTONS = { w: 48, h: 120 };
const MINIMAP = { w: 216, h: 166 };

export interface Area {
  x: number;
  y: number;
  w: number;
  h: number;
}

/** The part of the canvas nothing floats over (in the canvas's own pixels): the minimap takes
 * a corner, so the larger of the strip above it and the strip beside it. */
export function visibleArea(width: number, height: number, covered: { w: number; h: number }[] = []): Area {
  const corner = { w: Math.max(MINIMAP.w, ...covered.map((c) => c.w)), h: Math.max(MINIMAP.h, ...covered.map((c) => c.h)) };
  const above: Area = { x: LEFT_BUTTONS.w, y: TOP, w: width - LEFT_BUTTONS.w, h: height - TOP - corner.h };
  const beside: Area = { x: LEFT_BUTTONS.w, y: TOP, w: width - LEFT_BUTTONS.w - corner.w, h: height - TOP - 8 };
  return above.w * above.h >= beside.w * beside.h ? above : beside;
}

/** Bounds of nodes (and the wires between them, which may go round below). */
export function boundsOf(nodes: FlowNode[], edges: FlowEdge[] = []): [number, number, number, number] | null {
  if (!nodes.length) return null;
  let x0 = Infinity;
  let y0 = Infinity;
  let x1 = -Infinity;
  let y1 = -Infinity;
  const ids = new Set(nodes.map((n) => n.id));
  for (const n of nodes) {
    x0 = Math.min(x0, n.position.x - 10);
    y0 = Math.min(y0, n.position.y);
    x1 = Math.max(x1, n.position.x + (n.width ?? 210) + 10);
    y1 = Math.max(y1, n.position.y + (n.height ?? 60) + 22); // a block's error line hangs below it
  }
  for (const e of edges) {
    const b = e.data.route?.box;
    if (!b || !ids.has(e.source) || !ids.has(e.target)) continue;
    x0 = Math.min(x0, b[0]);
    y0 = Math.min(y0, b[1]);
    x1 = Math.max(x1, b[2]);
    y1 = Math.max(y1, b[3]);
  }
  return [x0, y0, x1, y1];
}

/** The viewport showing `bounds` in `area`: as large as fits (at most MAX_FIT_ZOOM), centred;
 * when that would be below READABLE_ZOOM, at READABLE_ZOOM from the bounds' top left. */
export function fitViewport(bounds: [number, number, number, number], area: Area): { x: number; y: number; zoom: number; clamped: boolean } {
  const [x0, y0, x1, y1] = bounds;
  const bw = Math.max(1, x1 - x0);
  const bh = Math.max(1, y1 - y0);
  const fit = Math.min((area.w - 2 * PAD) / bw, (area.h - 2 * PAD) / bh, MAX_FIT_ZOOM);
  if (fit >= READABLE_ZOOM) {
    const zoom = fit;
    return { x: area.x + (area.w - bw * zoom) / 2 - x0 * zoom, y: area.y + (area.h - bh * zoom) / 2 - y0 * zoom, zoom, clamped: false };
  }
  const zoom = READABLE_ZOOM;
  // too large to read whole: its top left, centred where it is narrower than the area
  const x = bw * zoom < area.w - 2 * PAD ? area.x + (area.w - bw * zoom) / 2 - x0 * zoom : area.x + PAD - x0 * zoom;
  const y = bh * zoom < area.h - 2 * PAD ? area.y + (area.h - bh * zoom) / 2 - y0 * zoom : area.y + PAD - y0 * zoom;
  return { x, y, zoom, clamped: true };
}

export function useViewMoves(rf: ReactFlowInstance) {
  // Moves of the view wait a frame or two for React Flow to measure what was just drawn.
  // Only the newest one may happen: a move scheduled earlier (a click on a problem centres
  // its block) must not land after, and undo, a fit the user asked for since.
  const pending = useRef<ReturnType<typeof setTimeout> | null>(null);
  const moveSoon = useCallback((move: () => void) => {
    if (pending.current !== null) clearTimeout(pending.current);
    pending.current = setTimeout(() => {
      pending.current = null;
      move();
    }, 30);
  }, []);
  const moveNow = useCallback((move: () => void) => {
    if (pending.current !== null) clearTimeout(pending.current);
    pending.current = null;
    move();
  }, []);

  /** Fit `nodes` (all drawn, or the selection) into what the canvas shows of itself. */
  const fit = useCallback(
    (nodes: FlowNode[], edges: FlowEdge[], duration = 0) => {
      const el = document.querySelector('.canvas');
      const b = boundsOf(nodes, edges);
      if (!el || !b) return;
      const r = el.getBoundingClientRect();
      const covered: { w: number; h: number }[] = [];
      const plot = el.querySelector('.plot-panel');
      if (plot) {
        const p = plot.getBoundingClientRect();
        covered.push({ w: r.right - p.left + 8, h: r.bottom - p.top + 8 });
      }
      const v = fitViewport(b, visibleArea(r.width, r.height, covered));
      rf.setViewport({ x: v.x, y: v.y, zoom: v.zoom }, { duration });
    },
    [rf],
  );
  return { moveSoon, moveNow, fit };
}
