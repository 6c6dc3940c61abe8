// Logged signals of a run, several in one panel on one time axis, with a time cursor: hovering
// a time moves it in every plot, and the canvas shows each plotted wire's value at that time.

import { useState } from 'react';
import type { ReactNode } from 'react';
import type { SignalData } from '../types';

export const COLORS = ['#2563eb', '#dc2626', '#16a34a', '#9333ea', '#ea580c', '#0891b2', '#ca8a04', '#db2777'];

export function ticks(lo: number, hi: number, n = 4): number[] {
  if (!(hi > lo)) return [lo];
  const step0 = (hi - lo) / n;
  const mag = 10 ** Math.floor(Math.log10(step0));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= step0) ?? step0;
  const out: number[] = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + 1e-9 * step; t += step) out.push(+t.toPrecision(12));
  return out;
}

/** The lines to draw: for (N, k, ...) one agent's k components; for (N,) the first 8 agents. */
export function signalLines(data: SignalData, agent: number): { label: string; ys: number[] }[] {
  const v0 = data.values[0];
  if (!Array.isArray(v0)) return [{ label: 'value', ys: data.values.map((v) => Number(v)) }];
  if (!Array.isArray(v0[0])) {
    const n = Math.min(8, v0.length);
    return Array.from({ length: n }, (_, j) => ({ label: `agent ${j}`, ys: data.values.map((v) => Number((v as number[])[j])) }));
  }
  const row = (v: unknown) => ((v as unknown[])[agent] as unknown[]).flat(2).map(Number);
  const k = Math.min(8, row(data.values[0]).length);
  return Array.from({ length: k }, (_, j) => ({ label: data.labels?.[j] ?? `[${agent}, ${j}]`, ys: data.values.map((v) => row(v)[j]) }));
}

/** Agents in a per-agent signal with components ((N, k): N), else 0. */
export function agentsOf(data: SignalData | null): number {
  return data && Array.isArray(data.values[0]) && Array.isArray((data.values[0] as unknown[])[0]) ? (data.values[0] as unknown[]).length : 0;
}

/** Index of the sample nearest time t. */
export function sampleAt(ts: number[], t: number): number {
  let lo = 0;
  let hi = ts.length - 1;
  if (hi < 0) return -1;
  while (lo < hi) {
    const m = (lo + hi) >> 1;
    if (ts[m] < t) lo = m + 1;
    else hi = m;
  }
  if (lo > 0 && Math.abs(ts[lo - 1] - t) <= Math.abs(ts[lo] - t)) return lo - 1;
  return lo;
}

const num = (v: number) => (Number.isFinite(v) ? String(+v.toPrecision(4)) : String(v));

/** A signal's value at time t as the canvas shows it (one agent's components). */
export function valueText(data: SignalData, agent: number, t: number): string {
  const i = sampleAt(data.t, t);
  if (i < 0) return '';
  const v = data.values[i];
  if (!Array.isArray(v)) return num(Number(v));
  if (!Array.isArray(v[0])) {
    const a = Math.min(agent, v.length - 1);
    return v.length > 1 ? `[${a}] ${num(Number(v[a]))}` : num(Number(v[0]));
  }
  const a = Math.min(agent, v.length - 1);
  const row = (v[a] as unknown[]).flat(2).map(Number);
  return `[${a}] ${row.length === 1 ? num(row[0]) : `(${row.slice(0, 4).map(num).join(', ')}${row.length > 4 ? ', …' : ''})`}`;
}

const W = 460;
const M = { l: 52, r: 12, t: 8, b: 18 };

function Subplot({ name, data, agent, t0, t1, cursor, last, height, onCursor, onRemove }: { name: string; data: SignalData | null; agent: number; t0: number; t1: number; cursor: number | null; last: boolean; height: number; onCursor: (t: number | null) => void; onRemove: (() => void) | null }) {
  const mb = last ? M.b + 20 : M.b; // the time axis's ticks and its label, under the last plot
  const H = height + (last ? 20 : 0);
  let body: ReactNode = <div className="muted pad">Loading {name}…</div>;
  let legend: { label: string; color: string }[] = [];
  if (data && data.t.length) {
    const lines = signalLines(data, agent);
    legend = lines.map((l, j) => ({ label: l.label, color: COLORS[j % COLORS.length] }));
    let lo = Infinity;
    let hi = -Infinity;
    for (const l of lines) for (const y of l.ys) if (Number.isFinite(y)) ((lo = Math.min(lo, y)), (hi = Math.max(hi, y)));
    if (!Number.isFinite(lo)) ((lo = 0), (hi = 1));
    if (!(hi > lo)) ((lo -= 1), (hi += 1));
    const pad = 0.05 * (hi - lo);
    lo -= pad;
    hi += pad;
    const x = (t: number) => M.l + ((t - t0) / (t1 - t0 || 1)) * (W - M.l - M.r);
    const y = (v: number) => H - mb - ((v - lo) / (hi - lo)) * (H - M.t - mb);
    const tOf = (px: number) => t0 + ((px - M.l) / (W - M.l - M.r)) * (t1 - t0);
    const yTicks = ticks(lo, hi, height < 140 ? 3 : 4);
    body = (
      <svg
        width={W}
        height={H}
        className="plot"
        data-testid="signal-plot"
        data-signal={name}
        onMouseMove={(e) => {
          const r = (e.currentTarget as SVGSVGElement).getBoundingClientRect();
          const px = e.clientX - r.left;
          onCursor(px < M.l || px > W - M.r ? null : Math.max(t0, Math.min(t1, tOf(px))));
        }}
        onMouseLeave={() => onCursor(null)}
      >
        {yTicks.map((v) => (
          <g key={`y${v}`}>
            <line x1={M.l} x2={W - M.r} y1={y(v)} y2={y(v)} className="grid" />
            <text x={M.l - 6} y={y(v) + 4} textAnchor="end">
              {+v.toPrecision(4)}
            </text>
          </g>
        ))}
        {last
          ? ticks(t0, t1).map((v) => (
              <text key={`x${v}`} x={x(v)} y={H - mb + 14} textAnchor="middle" className="x-tick">
                {+v.toPrecision(4)}
              </text>
            ))
          : null}
        {last ? (
          <text x={W - M.r} y={H - 4} textAnchor="end" className="axis-label">
            t [s]
          </text>
        ) : null}
        <line x1={M.l} x2={M.l} y1={M.t} y2={H - mb} className="axis" />
        <line x1={M.l} x2={W - M.r} y1={H - mb} y2={H - mb} className="axis" />
        {lines.map((l, j) => (
          <path key={j} d={l.ys.map((v, i) => `${i ? 'L' : 'M'}${x(data.t[i]).toFixed(1)},${y(Number.isFinite(v) ? v : lo).toFixed(1)}`).join('')} stroke={COLORS[j % COLORS.length]} fill="none" strokeWidth={1.5}>
            <title>{l.label}</title>
          </path>
        ))}
        {cursor !== null ? (
          <g className="cursor" data-testid="plot-cursor">
            <line x1={x(cursor)} x2={x(cursor)} y1={M.t} y2={H - mb} />
            {lines.map((l, j) => {
              const i = sampleAt(data.t, cursor);
              const v = l.ys[i];
              return Number.isFinite(v) ? <circle key={j} cx={x(data.t[i])} cy={y(v)} r={3} fill={COLORS[j % COLORS.length]} /> : null;
            })}
          </g>
        ) : null}
      </svg>
    );
  } else if (data) body = <div className="muted pad">No samples.</div>;
  return (
    <div className="subplot">
      <div className="subplot-head">
        <span className="mono">{name}</span>
        {data?.shape ? <span className="muted small"> ({Array.isArray(data.shape) ? data.shape.join(', ') : data.shape})</span> : null}
        {data && cursor !== null && data.t.length ? <span className="readout mono small"> t={num(data.t[sampleAt(data.t, cursor)])}: {valueText(data, agent, cursor)}</span> : null}
        {onRemove ? (
          <button className="link small" onClick={onRemove} aria-label={`Remove ${name} from the plot`} title="Remove from the plot">
            ×
          </button>
        ) : null}
      </div>
      {body}
      {legend.length > 1 ? (
        <div className="legend">
          {legend.map((l) => (
            <span key={l.label}>
              <i style={{ background: l.color }} />
              {l.label}
            </span>
          ))}
        </div>
      ) : null}
    </div>
  );
}

export interface Plotted {
  name: string;
  data: SignalData | null;
}

export function PlotPanel({ signals, onRemove, onClose, onCursor, agent, setAgent }: { signals: Plotted[]; onRemove: (name: string) => void; onClose: () => void; onCursor: (t: number | null) => void; agent: number; setAgent: (a: number) => void }) {
  const [cursor, setCursor] = useState<number | null>(null);
  const loaded = signals.filter((s) => s.data && s.data.t.length);
  const t0 = loaded.length ? Math.min(...loaded.map((s) => s.data!.t[0])) : 0;
  const t1 = loaded.length ? Math.max(...loaded.map((s) => s.data!.t[s.data!.t.length - 1])) : 1;
  const nAgents = Math.max(0, ...signals.map((s) => agentsOf(s.data)), ...signals.map((s) => (s.data && Array.isArray(s.data.values[0]) && !Array.isArray((s.data.values[0] as unknown[])[0]) ? (s.data.values[0] as unknown[]).length : 0)));
  const height = signals.length === 1 ? 200 : signals.length === 2 ? 130 : 100;
  const move = (t: number | null) => {
    setCursor(t);
    onCursor(t);
  };
  return (
    <div className="plot-panel" data-testid="plot-panel">
      <div className="plot-head">
        <span className="small">
          {signals.length === 1 ? 'Signal' : `${signals.length} signals`} <span className="muted">(Shift+click a wire to add one)</span>
        </span>
        {nAgents > 1 ? (
          <label className="small muted">
            {' '}agent{' '}
            <input className="agent-pick" type="number" min={0} max={nAgents - 1} value={agent} onChange={(e) => setAgent(Math.max(0, Math.min(nAgents - 1, Number(e.target.value) || 0)))} aria-label="Agent" />
          </label>
        ) : null}
        <button className="link" onClick={onClose} aria-label="Close the plot">
          ×
        </button>
      </div>
      <div className="subplots">
        {signals.map((s, i) => (
          <Subplot key={s.name} name={s.name} data={s.data} agent={agent} t0={t0} t1={t1} cursor={cursor} last={i === signals.length - 1} height={height} onCursor={move} onRemove={signals.length > 1 ? () => onRemove(s.name) : null} />
        ))}
      </div>
    </div>
  );
}
