// The diagram's numeric parameters as sliders (the live view's parameter model, docs/parameters.md):
// a slider sets `params: {"block.param": value}` in the document, the values a run uses
// without rebuilding anything, and the diagram runs again on the compiled engine, which
// keeps its program for the diagram's structure (no compile: a re-run takes the run's time).

import { useMemo } from 'react';
import type { Doc, Json, Palette, ValidationError } from '../types';
import { declOf } from '../model';
import { onField } from './Fields';

export interface Knob {
  key: string; // "block.param"
  block: string;
  param: string;
  value: number;
  lo: number;
  hi: number;
  step: number;
  unit?: string | null;
}

function niceStep(span: number): number {
  const raw = span / 200;
  const mag = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? raw;
}

/** One slider per scalar numeric parameter of the diagram's blocks: its range the declared
 * bounds where both are finite, else around its value (from the lower bound, if any). */
export function knobs(doc: Doc, palette: Palette | null): Knob[] {
  const out: Knob[] = [];
  const set = (doc.params ?? {}) as Record<string, Json>;
  const params = doc.parameters ?? {};
  const num = (v: Json | undefined): number | null => {
    if (typeof v === 'number' && Number.isFinite(v)) return v;
    if (typeof v === 'string' && v.startsWith('$')) return num(params[v.slice(1)]);
    return null;
  };
  for (const [name, b] of Object.entries(doc.blocks)) {
    const decl = declOf(palette, b.type);
    for (const p of decl?.params ?? []) {
      if (!p.numeric || !(p.kind === 'float' || p.kind === 'int' || p.kind === 'any')) continue;
      if (p.shape && p.shape !== '()' && p.shape !== '(N,)') continue;
      const key = `${name}.${p.name}`;
      const value = num(set[key]) ?? num(b[p.name]) ?? num(p.default ?? undefined);
      if (value === null) continue;
      const [blo, bhi] = p.bounds ?? [null, null];
      let lo = blo !== null && blo !== undefined && Number.isFinite(blo) ? blo : null;
      let hi = bhi !== null && bhi !== undefined && Number.isFinite(bhi) ? bhi : null;
      const mag = Math.max(Math.abs(value), 1);
      if (lo === null) lo = value >= 0 ? 0 : value - 2 * mag;
      if (hi === null) hi = Math.max(lo + 2 * mag, value + mag, 2 * value);
      if (!(hi > lo)) continue;
      out.push({ key, block: name, param: p.name, value: Math.min(hi, Math.max(lo, value)), lo, hi, step: niceStep(hi - lo), unit: p.unit });
    }
  }
  return out;
}

export function TunePanel({
  doc,
  palette,
  errors,
  onSet,
  onReset,
  auto,
  setAuto,
  note,
}: {
  doc: Doc;
  palette: Palette | null;
  errors: ValidationError[];
  onSet: (key: string, v: number) => void;
  onReset: () => void;
  auto: boolean;
  setAuto: (a: boolean) => void;
  note: string | null;
}) {
  const ks = useMemo(() => knobs(doc, palette), [doc, palette]);
  const set = (doc.params ?? {}) as Record<string, Json>;
  const byBlock = new Map<string, Knob[]>();
  for (const k of ks) byBlock.set(k.block, [...(byBlock.get(k.block) ?? []), k]);
  return (
    <div className="inspector tune" data-testid="tune">
      <div className="muted small pad-b">
        Numeric parameters: a change applies at the next run without rebuilding the diagram (the scenario's <span className="mono">params:</span>). With re-run on, the diagram runs again on the
        compiled engine (JAX), which keeps its program for this structure, and the plotted signals follow.
      </div>
      <label className="row small">
        <input type="checkbox" checked={auto} onChange={(e) => setAuto(e.target.checked)} data-testid="tune-auto" /> re-run on change
      </label>
      {note ? (
        <div className="tune-note small mono" data-testid="tune-note">
          {note}
        </div>
      ) : null}
      {!ks.length ? <div className="muted pad">No numeric parameters with a number to start from.</div> : null}
      {[...byBlock].map(([block, list]) => (
        <div key={block}>
          <div className="insp-section">{block}</div>
          {list.map((k) => {
            const err = errors.filter((e) => e.field === `params.${k.key}` || (e.field === 'params' && e.message.includes(k.key)));
            return (
              <div key={k.key} className={`knob ${k.key in set ? 'set' : ''}`} data-knob={k.key}>
                <div className="param-head">
                  <span className="mono">{k.param}</span>
                  <span className="muted small">
                    {' '}
                    {k.lo} … {+k.hi.toPrecision(6)}
                    {k.unit ? ` [${k.unit}]` : ''}
                  </span>
                  <span className="knob-value mono">{+k.value.toPrecision(6)}</span>
                </div>
                <input
                  type="range"
                  min={k.lo}
                  max={k.hi}
                  step={k.step}
                  value={k.value}
                  aria-label={k.key}
                  data-testid={`knob-${k.key}`}
                  onChange={(e) => onSet(k.key, Number(Number(e.target.value).toPrecision(10)))}
                />
                {err.map((e, i) => (
                  <div key={i} className="vf-err">
                    {onField(e.message, e.field)}
                  </div>
                ))}
              </div>
            );
          })}
        </div>
      ))}
      {Object.keys(set).length ? (
        <div className="row">
          <button onClick={onReset} data-testid="tune-reset">
            Back to the blocks' own values
          </button>
        </div>
      ) : null}
    </div>
  );
}
