// The right panel's Properties: the selected block's parameters, a subsystem, a wire, a
// selection, or (nothing selected) the diagram itself: its name, parameters and run settings.

import { useEffect, useState } from 'react';
import type { Doc, Json, Palette, ValidationError } from '../types';
import { declOf } from '../model';
import { onField, ParamField, ValueField } from './Fields';
import { PortTable } from './Palette';
import { Rich } from './Text';

/** The errors a check gave about one document entry (`blocks.drive.gain`, `parameters.agents`). */
export function errorsOn(errors: ValidationError[], field: string, param?: string): string[] {
  return errors
    .filter((e) => e.field === field || (param !== undefined && (e.refs ?? []).includes(param)))
    .map((e) => (e.field === field ? e.message : `${e.field?.replace(/^blocks\./, '') ?? ''}: ${onField(e.message, e.field)}`));
}

export function BlockPanel({
  doc,
  name,
  palette,
  errors,
  onRename,
  onParam,
}: {
  doc: Doc;
  name: string;
  palette: Palette | null;
  errors: ValidationError[];
  onRename: (to: string) => string | null;
  onParam: (key: string, v: Json | undefined) => void;
}) {
  const b = doc.blocks[name];
  const decl = b ? declOf(palette, b.type) : null;
  const [nm, setNm] = useState(name);
  const [nameErr, setNameErr] = useState<string | null>(null);
  useEffect(() => {
    setNm(name);
    setNameErr(null);
  }, [name]);
  if (!b) return null;
  const refs = Object.keys(doc.parameters ?? {}).map((k) => `$${k}`);
  const declared = new Set((decl?.params ?? []).map((p) => p.name));
  const extra = Object.keys(b).filter((k) => k !== 'type' && !declared.has(k));
  const mine = errors.filter((e) => e.block === name);
  // errors about the block itself: not about one of its parameters (shown on the field) or ports
  const own = mine.filter((e) => !(e.field ?? '').startsWith(`blocks.${name}.`) && !e.port);
  const commitName = () => {
    if (nm === name) return;
    const r = onRename(nm);
    setNameErr(r);
  };
  const field = (k: string) => `blocks.${name}.${k}`;
  return (
    <div className="inspector" data-testid="block-panel">
      <div className="insp-title">
        <input
          className={`name-field ${nameErr ? 'bad' : ''}`}
          value={nm}
          aria-label="Block name"
          onChange={(e) => setNm(e.target.value)}
          onBlur={commitName}
          onKeyDown={(e) => {
            if (e.key === 'Enter') commitName();
            if (e.key === 'Escape') setNm(name);
          }}
        />
        <div className="mono muted small">{b.type}</div>
        {nameErr ? <div className="vf-err">{nameErr}</div> : null}
      </div>
      {decl?.summary ? (
        <div className="insp-summary">
          <Rich text={decl.summary} />
        </div>
      ) : null}
      {!decl ? <div className="vf-err">unknown block type {b.type}</div> : null}
      {own.map((e, i) => (
        <div key={i} className="insp-error" data-testid="block-error">
          {e.message}
        </div>
      ))}
      {decl ? (
        <details className="insp-ports">
          <summary>Ports</summary>
          <PortTable decl={decl} />
        </details>
      ) : null}
      <div className="insp-section">Parameters</div>
      {(decl?.params ?? []).map((p) => (
        <ParamField
          key={`${name}-${p.name}`}
          decl={p}
          value={b[p.name]}
          refs={refs}
          generators={palette?.generators ?? []}
          errors={errorsOn(errors, field(p.name))}
          field={field(p.name)}
          onCommit={(v) => onParam(p.name, v)}
        />
      ))}
      {extra.map((k) => (
        <ParamField
          key={`${name}-x-${k}`}
          decl={{ name: k, kind: 'any' }}
          value={b[k]}
          refs={refs}
          generators={palette?.generators ?? []}
          errors={errorsOn(errors, field(k))}
          field={field(k)}
          onCommit={(v) => onParam(k, v)}
        />
      ))}
      {decl?.doc ? (
        <details className="insp-doc">
          <summary>Documentation</summary>
          <pre>{decl.doc}</pre>
        </details>
      ) : null}
    </div>
  );
}

export const SIM_KEYS = ['t_final', 'dt', 'solver', 'seed'] as const;

export function DiagramPanel({
  doc,
  errors,
  onField: onDocField,
  onParameter,
  onSimulation,
}: {
  doc: Doc;
  errors: ValidationError[];
  onField: (key: 'name' | 'description', v: string) => void;
  onParameter: (key: string, v: Json | undefined) => void;
  onSimulation: (key: string, v: Json | undefined) => void;
}) {
  const [newKey, setNewKey] = useState('');
  const refs = Object.keys(doc.parameters ?? {}).map((k) => `$${k}`);
  const params = Object.entries(doc.parameters ?? {});
  const sections = errors.filter((e) => e.field && !/^(blocks|parameters|simulation)\./.test(e.field));
  return (
    <div className="inspector" data-testid="diagram-panel">
      <div className="insp-section">Diagram</div>
      <label className="row">
        <span>name</span>
        <input value={doc.name ?? ''} onChange={(e) => onDocField('name', e.target.value)} aria-label="Diagram name" />
      </label>
      <label className="row col">
        <span>description</span>
        <textarea rows={3} value={doc.description ?? ''} onChange={(e) => onDocField('description', e.target.value)} />
      </label>
      <div className="insp-section">Parameters</div>
      <div className="muted small pad-b">Referenced from blocks as $name. The agent count is one of them.</div>
      {params.map(([k, v]) => (
        <div key={k} className={`param ${k === 'agents' ? 'agents' : ''}`} data-param={k}>
          <div className="param-head">
            <span className="mono">{k}</span>
            <button className="link small reset" title={`Remove ${k}`} onClick={() => onParameter(k, undefined)}>
              remove
            </button>
          </div>
          <ValueField
            value={v}
            refs={refs}
            field={`parameters.${k}`}
            errors={errorsOn(errors, `parameters.${k}`, k)}
            onCommit={(x) => onParameter(k, x === undefined ? null : x)}
            testid={`dparam-${k}`}
          />
        </div>
      ))}
      <div className="row">
        <input placeholder="new parameter" value={newKey} onChange={(e) => setNewKey(e.target.value)} aria-label="New parameter name" />
        <button
          disabled={!/^[A-Za-z_]\w*$/.test(newKey) || newKey in (doc.parameters ?? {})}
          onClick={() => {
            onParameter(newKey, 0);
            setNewKey('');
          }}
        >
          add
        </button>
      </div>
      <div className="insp-section">Simulation</div>
      {SIM_KEYS.map((k) => (
        <div key={k} className="param" data-param={`simulation.${k}`}>
          <div className="param-head">
            <span className="mono">{k}</span>
          </div>
          <ValueField
            value={doc.simulation?.[k]}
            refs={refs}
            field={`simulation.${k}`}
            errors={errorsOn(errors, `simulation.${k}`)}
            onCommit={(x) => onSimulation(k, x)}
            testid={`sim-${k}`}
          />
        </div>
      ))}
      {sections.length ? <div className="insp-section">Outcome and figures</div> : null}
      {sections.map((e, i) => (
        <div key={i} className="insp-error">
          {e.message}
        </div>
      ))}
    </div>
  );
}

export function GroupPanel({ doc, name, onLabel, onOpen, onUngroup }: { doc: Doc; name: string; onLabel: (l: string) => void; onOpen: () => void; onUngroup: () => void }) {
  const g = doc.editor?.groups?.[name];
  if (!g) return null;
  return (
    <div className="inspector">
      <div className="insp-section">Subsystem</div>
      <label className="row">
        <span>label</span>
        <input value={g.label ?? name} onChange={(e) => onLabel(e.target.value)} />
      </label>
      <div className="muted small pad-b">
        {g.blocks.length} blocks{g.groups?.length ? `, ${g.groups.length} subsystems` : ''}. Its ports are the wires its boundary cuts; it runs exactly as the flat diagram.
      </div>
      <div className="row">
        <button onClick={onOpen}>Open</button>
        <button onClick={onUngroup}>Ungroup</button>
      </div>
    </div>
  );
}

export function WirePanel({
  wire,
  shape,
  errors,
  logged,
  inLog,
  onLog,
  onDelete,
}: {
  wire: [string, string];
  shape?: string;
  errors: string[];
  logged: string[] | null;
  inLog: boolean;
  onLog: () => void;
  onDelete: () => void;
}) {
  const isLogged = logged ? logged.includes(wire[0]) : null;
  return (
    <div className="inspector" data-testid="wire-panel">
      <div className="insp-section">Wire</div>
      <div className="mono">
        {wire[0]} → {wire[1]}
      </div>
      <div className="muted small pad-b">signal {shape ?? '(shape known once it builds)'}</div>
      {errors.map((e, i) => (
        <div key={i} className="insp-error">
          {e}
        </div>
      ))}
      {isLogged === false && !inLog ? (
        <div className="row">
          <span className="small">not logged in the last run</span>
          <button onClick={onLog}>Log it</button>
        </div>
      ) : null}
      {inLog && isLogged === false ? <div className="muted small pad-b">Logged from the next run on.</div> : null}
      {isLogged ? <div className="muted small pad-b">Logged: click it to plot its signal; Shift+click adds it to the plot.</div> : null}
      <div className="row">
        <button onClick={onDelete}>Delete the wire</button>
      </div>
    </div>
  );
}

export function SelectionPanel({ count, onGroup, onDelete }: { count: number; onGroup: () => void; onDelete: () => void }) {
  return (
    <div className="inspector">
      <div className="insp-section">{count} selected</div>
      <div className="row">
        <button onClick={onGroup}>Group (Ctrl+G)</button>
        <button onClick={onDelete}>Delete</button>
      </div>
    </div>
  );
}
