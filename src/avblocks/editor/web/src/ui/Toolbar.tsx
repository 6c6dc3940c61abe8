// The toolbar: file, edit, run (engine, final time and step for this run), export, the check.

import type { Json } from '../types';
import { valueToText } from '../model';

export interface RunFields {
  tFinal: string;
  dt: string;
  setTFinal: (v: string) => void;
  setDt: (v: string) => void;
  /** messages on each field (text not read, or the check's words about the value) */
  errors: { t_final: string[]; dt: string[] };
}

function NumField({ label, sub, value, placeholder, onChange, errors, title }: { label: string; sub?: string; value: string; placeholder: string; onChange: (v: string) => void; errors: string[]; title: string }) {
  return (
    <label title={errors.length ? errors.join('\n') : title} className={`tb-field ${errors.length ? 'bad' : ''}`}>
      {label}
      {sub ? <sub>{sub}</sub> : null}
      <input className={`num ${errors.length ? 'bad' : ''}`} value={value} placeholder={placeholder} onChange={(e) => onChange(e.target.value)} aria-label={`${label}${sub ? `_${sub}` : ''}`} aria-invalid={errors.length > 0} />
      {errors.length ? (
        <div className="tb-err" data-testid={`${label}${sub ? `_${sub}` : ''}-error`}>
          {errors[0]}
        </div>
      ) : null}
    </label>
  );
}

export function Toolbar({
  title,
  dirty,
  canUndo,
  canRedo,
  backend,
  setBackend,
  fields,
  sim,
  running,
  progress,
  check,
  actions,
}: {
  title: string;
  dirty: boolean;
  canUndo: boolean;
  canRedo: boolean;
  backend: string;
  setBackend: (b: string) => void;
  fields: RunFields;
  sim: { t_final?: Json; dt?: Json };
  running: boolean;
  progress: number;
  check: { text: string; cls: string; fresh: boolean };
  actions: {
    newDoc: () => void;
    open: () => void;
    save: () => void;
    saveAs: () => void;
    undo: () => void;
    redo: () => void;
    group: () => void;
    layout: () => void;
    run: () => void;
    stop: () => void;
    live: () => void;
    exportAs: (f: 'python' | 'svg' | 'png') => void;
    help: () => void;
    problems: () => void;
  };
}) {
  const a = actions;
  return (
    <header className="toolbar">
      <div className="brand">
        avblocks <span className="muted">editor</span>
      </div>
      <div className="file-title" title={title} data-testid="file-title">
        {title}
        {dirty ? <span className="dirty" title="unsaved changes"> ●</span> : null}
      </div>
      <div className="tb-group">
        <button onClick={a.newDoc} title="New diagram">New</button>
        <button onClick={a.open} title="Open (Ctrl+O)">Open</button>
        <button onClick={a.save} title="Save (Ctrl+S)" data-testid="save">Save</button>
        <button onClick={a.saveAs} title="Save as (Ctrl+Shift+S)">Save as</button>
      </div>
      <div className="tb-group">
        <button onClick={a.undo} disabled={!canUndo} title="Undo (Ctrl+Z)" data-testid="undo">↶</button>
        <button onClick={a.redo} disabled={!canRedo} title="Redo (Ctrl+Shift+Z)" data-testid="redo">↷</button>
        <button onClick={a.group} title="Group the selection (Ctrl+G)">Group</button>
        <button onClick={a.layout} title="Automatic layout (L)">Layout</button>
      </div>
      <div className="tb-group run-group">
        <select value={backend} onChange={(e) => setBackend(e.target.value)} aria-label="Backend" title="Engine">
          <option value="numpy">NumPy</option>
          <option value="jax">JAX</option>
        </select>
        <NumField label="t" sub="final" value={fields.tFinal} placeholder={sim.t_final === undefined ? '' : valueToText(sim.t_final)} onChange={fields.setTFinal} errors={fields.errors.t_final} title="final time of this run [s] (empty: the diagram's)" />
        <NumField label="dt" value={fields.dt} placeholder={sim.dt === undefined ? '' : valueToText(sim.dt)} onChange={fields.setDt} errors={fields.errors.dt} title="major step of this run [s] (empty: the diagram's)" />
        {running ? (
          <button className="danger" onClick={a.stop} data-testid="stop">
            Stop
          </button>
        ) : (
          <button className="primary" onClick={a.run} title="Run (Ctrl+Enter)" data-testid="run">
            ▶ Run
          </button>
        )}
        <button onClick={a.live} title="Open the drawn diagram in the live view">Live</button>
      </div>
      <div className="tb-group">
        <select value="" onChange={(e) => e.target.value && a.exportAs(e.target.value as 'python' | 'svg' | 'png')} aria-label="Export" title="Export">
          <option value="">Export…</option>
          <option value="python">Python script</option>
          <option value="svg">SVG</option>
          <option value="png">PNG</option>
        </select>
        <button onClick={a.help} title="Keyboard shortcuts (?)">?</button>
      </div>
      <div className={`check ${check.cls}`} data-testid="check" data-fresh={String(check.fresh)} onClick={a.problems}>
        {check.text}
      </div>
      {running ? (
        <div className="progress" data-testid="progress">
          <div style={{ width: `${Math.round(100 * progress)}%` }} />
        </div>
      ) : null}
    </header>
  );
}
