// Side panels: palette, parameters, diagram parameters, problems, run results, dialogs.

import { useEffect, useMemo, useRef, useState } from 'react';
import type { ReactNode } from 'react';
import type { BlockDecl, Doc, FileList, GeneratorDecl, Json, Palette, ParamDecl, RunStatus, SignalData, ValidationError } from './types';
import { checkNumber, declOf, generatorOf, ModelError, parseValue, valueToText } from './model';

// ---------------------------------------------------------------- palette

export const DRAG_MIME = 'application/x-avblocks-type';

function matches(b: BlockDecl, q: string): boolean {
  if (!q) return true;
  const hay = `${b.type} ${b.name} ${b.summary ?? ''}`.toLowerCase();
  return q
    .toLowerCase()
    .split(/\s+/)
    .every((w) => hay.includes(w));
}

export function PalettePanel({
  palette,
  onAdd,
  searchRef,
}: {
  palette: Palette | null;
  onAdd: (type: string) => void;
  searchRef: React.RefObject<HTMLInputElement | null>;
}) {
  const [q, setQ] = useState('');
  const [shown, setShown] = useState<string | null>(null);
  const [open, setOpen] = useState<Record<string, boolean>>({});
  const [cursor, setCursor] = useState(0);
  const found = useMemo(() => (palette ? palette.families.flatMap((f) => f.blocks.filter((b) => matches(b, q))) : []), [palette, q]);
  useEffect(() => setCursor(0), [q]);
  if (!palette) return <div className="palette"><div className="muted pad">Loading the palette…</div></div>;
  const detail = shown ? declOf(palette, shown) : q && found[cursor] ? found[cursor] : null;
  return (
    <div className="palette">
      <div className="palette-search">
        <input
          ref={searchRef}
          type="search"
          placeholder="Search blocks   ( / )"
          value={q}
          aria-label="Search blocks"
          onChange={(e) => setQ(e.target.value)}
          onKeyDown={(e) => {
            if (e.key === 'ArrowDown') {
              setCursor((c) => Math.min(found.length - 1, c + 1));
              e.preventDefault();
            } else if (e.key === 'ArrowUp') {
              setCursor((c) => Math.max(0, c - 1));
              e.preventDefault();
            } else if (e.key === 'Enter' && found[cursor]) {
              onAdd(found[cursor].type);
              setQ('');
              (e.target as HTMLInputElement).blur();
            } else if (e.key === 'Escape') {
              setQ('');
              (e.target as HTMLInputElement).blur();
            }
          }}
        />
      </div>
      <div className="palette-list">
        {palette.families.map((f) => {
          const blocks = f.blocks.filter((b) => matches(b, q));
          if (!blocks.length) return null;
          const isOpen = q ? true : open[f.name] ?? true;
          return (
            <div key={f.name} className={`family fam-${f.name}`}>
              <button className="family-head" onClick={() => setOpen({ ...open, [f.name]: !isOpen })}>
                <span className="caret">{isOpen ? '▾' : '▸'}</span> {f.title} <span className="count">{blocks.length}</span>
              </button>
              {isOpen
                ? blocks.map((b) => (
                    <div
                      key={b.type}
                      className={`palette-item fam-${f.name} ${q && found[cursor]?.type === b.type ? 'cursor' : ''} ${shown === b.type ? 'shown' : ''}`}
                      draggable
                      tabIndex={0}
                      data-type={b.type}
                      onDragStart={(e) => {
                        e.dataTransfer.setData(DRAG_MIME, b.type);
                        e.dataTransfer.setData('text/plain', b.type);
                        e.dataTransfer.effectAllowed = 'copy';
                      }}
                      onMouseEnter={() => setShown(b.type)}
                      onMouseLeave={() => setShown(null)}
                      onFocus={() => setShown(b.type)}
                      onDoubleClick={() => onAdd(b.type)}
                      onKeyDown={(e) => {
                        if (e.key === 'Enter') onAdd(b.type);
                      }}
                      title="Drag onto the canvas, or double-click / Enter to add"
                    >
                      <button
                        className="pi-add"
                        title={`Add ${b.name} to the canvas`}
                        aria-label={`Add ${b.name}`}
                        onClick={(e) => {
                          e.stopPropagation();
                          onAdd(b.type);
                        }}
                      >
                        +
                      </button>
                      <div className="pi-name">{b.name}</div>
                      <div className="pi-summary">{b.summary}</div>
                    </div>
                  ))
                : null}
            </div>
          );
        })}
        {q && !found.length ? <div className="muted pad">No block matches “{q}”.</div> : null}
      </div>
      {detail ? <BlockCard decl={detail} /> : <div className="palette-hint muted">Hover a block to see its ports and parameters. Drag it onto the canvas, or search and press Enter.</div>}
    </div>
  );
}

export function PortTable({ decl }: { decl: BlockDecl }) {
  const rows = [...decl.inputs.map((p) => ({ ...p, dir: 'in' })), ...decl.outputs.map((p) => ({ ...p, dir: 'out' }))];
  if (!rows.length) return <div className="muted">No ports.</div>;
  return (
    <table className="port-table">
      <thead>
        <tr>
          <th></th>
          <th>port</th>
          <th>shape</th>
          <th>unit</th>
        </tr>
      </thead>
      <tbody>
        {rows.map((p) => (
          <tr key={`${p.dir}-${p.name}`} title={p.doc}>
            <td className={`dir ${p.dir}`}>{p.dir === 'in' ? '→' : '←'}</td>
            <td className="mono">{p.name}</td>
            <td className="mono">{p.shape}</td>
            <td>{p.unit ?? ''}</td>
          </tr>
        ))}
      </tbody>
    </table>
  );
}

function BlockCard({ decl }: { decl: BlockDecl }) {
  return (
    <div className="block-card" data-testid="block-card">
      <div className="bc-title">
        {decl.name} <span className="mono muted">{decl.type}</span>
      </div>
      {decl.summary ? <div className="bc-summary">{decl.summary}</div> : null}
      <PortTable decl={decl} />
      {decl.params.length ? (
        <div className="bc-params">
          {decl.params.map((p) => (
            <div key={p.name} className="bc-param" title={p.doc}>
              <span className="mono">{p.name}</span> <span className="muted">{p.kind}</span>
              {p.default !== null && p.default !== undefined ? <span className="muted"> = {valueToText(p.default)}</span> : null}
              {p.required ? <span className="req"> required</span> : null}
              {p.unit ? <span className="muted"> [{p.unit}]</span> : null}
            </div>
          ))}
        </div>
      ) : null}
    </div>
  );
}

// ---------------------------------------------------------------- value fields

function jsonEq(a: unknown, b: unknown): boolean {
  return JSON.stringify(a) === JSON.stringify(b);
}

/** A text field holding one value (JSON with bare `$names`); commits parsed values. */
export function ValueField({
  value,
  onCommit,
  kind = 'any',
  bounds,
  multiline = false,
  placeholder,
  refs,
  testid,
}: {
  value: Json | undefined;
  onCommit: (v: Json | undefined) => void;
  kind?: string;
  bounds?: [number | null, number | null] | null;
  multiline?: boolean;
  placeholder?: string;
  refs: string[];
  testid?: string;
}) {
  const [text, setText] = useState(valueToText(value));
  const [err, setErr] = useState<string | null>(null);
  useEffect(() => {
    let cur: Json | undefined;
    try {
      cur = text.trim() === '' ? undefined : parseValue(text);
    } catch {
      cur = Symbol() as unknown as Json;
    }
    if (!jsonEq(cur, value)) {
      setText(valueToText(value));
      setErr(null);
    }
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [value]);
  const listId = useMemo(() => `refs-${Math.random().toString(36).slice(2)}`, []);
  const change = (t: string) => {
    setText(t);
    if (t.trim() === '') {
      setErr(null);
      onCommit(undefined);
      return;
    }
    let v: Json;
    try {
      v = parseValue(t);
    } catch (e) {
      setErr(e instanceof ModelError ? e.message : String(e));
      return;
    }
    if (typeof v === 'string' && v.startsWith('$') && !refs.includes(v)) {
      setErr(`no diagram parameter ${v}`);
    } else if (kind === 'float' || kind === 'int') {
      setErr(checkNumber(v, kind, bounds));
    } else setErr(null);
    onCommit(v);
  };
  const props = {
    value: text,
    placeholder,
    className: `vf ${err ? 'bad' : ''}`,
    spellCheck: false,
    'data-testid': testid,
    onChange: (e: React.ChangeEvent<HTMLInputElement | HTMLTextAreaElement>) => change(e.target.value),
  };
  return (
    <div className="vf-wrap">
      {multiline ? (
        <textarea rows={Math.min(6, Math.max(2, Math.ceil(text.length / 34)))} {...props} />
      ) : (
        <>
          <input list={listId} {...props} />
          <datalist id={listId}>
            {refs.map((r) => (
              <option key={r} value={r} />
            ))}
          </datalist>
        </>
      )}
      {err ? <div className="vf-err">{err}</div> : null}
    </div>
  );
}

function GeneratorField({
  value,
  onCommit,
  generators,
  refs,
  param,
}: {
  value: Json | undefined;
  onCommit: (v: Json | undefined) => void;
  generators: GeneratorDecl[];
  refs: string[];
  param: string;
}) {
  const names = generators.map((g) => g.name);
  const gen = generatorOf(value, names);
  const mode = value === undefined ? '' : gen ? gen.name : typeof value === 'string' && value.startsWith('$') ? '$' : 'literal';
  const setMode = (m: string) => {
    if (m === '') onCommit(undefined);
    else if (m === 'literal') onCommit(gen ? [] : value ?? []);
    else if (m === '$') onCommit(refs[0] ?? '$agents');
    else {
      const g = generators.find((x) => x.name === m)!;
      const args: Record<string, Json> = {};
      for (const a of g.args) {
        if (a.name === 'n') args.n = '$agents';
        else if (a.name === 'seed') args.seed = refs.includes('$seed') ? '$seed' : 0;
        else if (a.required) args[a.name] = a.default ?? (a.kind === 'int' || a.kind === 'float' ? 1 : null);
      }
      onCommit({ [m]: args });
    }
  };
  const g = gen ? generators.find((x) => x.name === gen.name) : null;
  return (
    <div className="gen">
      <select value={mode} onChange={(e) => setMode(e.target.value)} data-testid={`gen-${param}`}>
        <option value="">(not set)</option>
        <optgroup label="generator">
          {generators.map((x) => (
            <option key={x.name} value={x.name} title={x.doc}>
              {x.name}
            </option>
          ))}
        </optgroup>
        <option value="literal">literal array</option>
        <option value="$">diagram parameter</option>
      </select>
      {g && gen ? (
        <div className="gen-args">
          {g.doc ? <div className="muted small">{g.doc.split('\n')[0]}</div> : null}
          {g.args.map((a) => (
            <label key={a.name} className="gen-arg" title={a.doc}>
              <span className="mono">
                {a.name}
                {a.required ? '*' : ''}
              </span>
              <ValueField
                value={gen.args[a.name]}
                refs={refs}
                kind={a.kind}
                placeholder={a.default !== undefined && a.default !== null ? valueToText(a.default) : ''}
                onCommit={(v) => {
                  const args = { ...gen.args };
                  if (v === undefined) delete args[a.name];
                  else args[a.name] = v;
                  onCommit({ [gen.name]: args });
                }}
              />
            </label>
          ))}
        </div>
      ) : mode === 'literal' || mode === '$' ? (
        <ValueField value={value} refs={refs} onCommit={onCommit} multiline={mode === 'literal'} />
      ) : null}
    </div>
  );
}

export function ParamField({
  decl,
  value,
  onCommit,
  refs,
  generators,
  errors,
}: {
  decl: ParamDecl;
  value: Json | undefined;
  onCommit: (v: Json | undefined) => void;
  refs: string[];
  generators: GeneratorDecl[];
  errors: string[];
}) {
  const k = decl.kind;
  const isRef = typeof value === 'string' && value.startsWith('$');
  const def = decl.default !== null && decl.default !== undefined ? valueToText(decl.default) : '';
  let field: ReactNode;
  if (k === 'bool' && !isRef) {
    const cur = value === undefined ? decl.default === true : value === true;
    field = <input type="checkbox" checked={cur} onChange={(e) => onCommit(e.target.checked)} data-testid={`param-${decl.name}`} />;
  } else if (k === 'choice' && decl.choices && !isRef) {
    field = (
      <select value={value === undefined ? '' : String(value)} onChange={(e) => onCommit(e.target.value === '' ? undefined : (decl.choices!.find((c) => String(c) === e.target.value) ?? e.target.value))} data-testid={`param-${decl.name}`}>
        <option value="">{def ? `default (${def})` : '(not set)'}</option>
        {decl.choices.map((c) => (
          <option key={String(c)} value={String(c)}>
            {String(c)}
          </option>
        ))}
      </select>
    );
  } else if (k === 'per_agent') {
    field = <GeneratorField value={value} onCommit={onCommit} generators={generators} refs={refs} param={decl.name} />;
  } else {
    const multi = !['float', 'int', 'str', 'bool', 'choice'].includes(k);
    field = (
      <ValueField
        value={value}
        onCommit={onCommit}
        kind={k}
        bounds={decl.bounds}
        multiline={multi && (value === undefined ? false : valueToText(value).length > 30)}
        placeholder={def || (decl.required ? 'required' : '')}
        refs={refs}
        testid={`param-${decl.name}`}
      />
    );
  }
  const b = decl.bounds;
  const range = b && (b[0] !== null || b[1] !== null) ? `${b[0] ?? '−∞'} … ${b[1] ?? '∞'}` : '';
  return (
    <div className={`param ${errors.length ? 'bad' : ''}`} data-param={decl.name}>
      <div className="param-head" title={decl.doc}>
        <span className="mono">{decl.name}</span>
        {decl.required ? <span className="req">*</span> : null}
        <span className="muted small">
          {' '}
          {k}
          {decl.shape && decl.shape !== '()' ? ` ${decl.shape}` : ''}
          {decl.unit ? ` [${decl.unit}]` : ''}
          {range ? ` ${range}` : ''}
        </span>
        {value !== undefined ? (
          <button className="link small reset" title="Remove (use the default)" onClick={() => onCommit(undefined)}>
            reset
          </button>
        ) : null}
      </div>
      {field}
      {errors.map((e, i) => (
        <div key={i} className="vf-err">
          {e}
        </div>
      ))}
    </div>
  );
}

// ---------------------------------------------------------------- inspector

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
  const commitName = () => {
    if (nm === name) return;
    const r = onRename(nm);
    setNameErr(r);
  };
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
      {decl?.summary ? <div className="insp-summary">{decl.summary}</div> : null}
      {!decl ? <div className="vf-err">unknown block type {b.type}</div> : null}
      {mine.filter((e) => !e.param).map((e, i) => (
        <div key={i} className="insp-error">
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
          errors={mine.filter((e) => e.param === p.name).map((e) => e.message)}
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
          errors={mine.filter((e) => e.param === k).map((e) => e.message)}
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

export function DiagramPanel({
  doc,
  onField,
  onParameter,
  onSimulation,
}: {
  doc: Doc;
  onField: (key: 'name' | 'description', v: string) => void;
  onParameter: (key: string, v: Json | undefined) => void;
  onSimulation: (key: string, v: Json | undefined) => void;
}) {
  const [newKey, setNewKey] = useState('');
  const refs = Object.keys(doc.parameters ?? {}).map((k) => `$${k}`);
  const params = Object.entries(doc.parameters ?? {});
  return (
    <div className="inspector" data-testid="diagram-panel">
      <div className="insp-section">Diagram</div>
      <label className="row">
        <span>name</span>
        <input value={doc.name ?? ''} onChange={(e) => onField('name', e.target.value)} aria-label="Diagram name" />
      </label>
      <label className="row col">
        <span>description</span>
        <textarea rows={3} value={doc.description ?? ''} onChange={(e) => onField('description', e.target.value)} />
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
          <ValueField value={v} refs={refs} onCommit={(x) => onParameter(k, x === undefined ? null : x)} testid={`dparam-${k}`} />
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
      {['t_final', 'dt', 'solver', 'seed'].map((k) => (
        <div key={k} className="param" data-param={`simulation.${k}`}>
          <div className="param-head">
            <span className="mono">{k}</span>
          </div>
          <ValueField value={doc.simulation?.[k]} refs={refs} onCommit={(x) => onSimulation(k, x)} testid={`sim-${k}`} />
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
      {isLogged ? <div className="muted small pad-b">Logged: its plot is shown on the canvas.</div> : null}
      <div className="row">
        <button onClick={onDelete}>Delete the wire</button>
      </div>
    </div>
  );
}

// ---------------------------------------------------------------- problems

export function ProblemsPanel({ errors, onPick, validating }: { errors: ValidationError[]; onPick: (e: ValidationError) => void; validating: boolean }) {
  return (
    <div className="problems" data-testid="problems">
      {errors.length === 0 ? (
        <div className="muted pad">{validating ? 'Checking…' : 'No problems: the diagram builds.'}</div>
      ) : (
        errors.map((e, i) => (
          <button key={i} className="problem" onClick={() => onPick(e)} title="Show it on the canvas">
            <span className="p-kind">{e.kind ?? 'Error'}</span>
            <span className="p-where mono">{[e.block, e.port ?? e.param].filter(Boolean).join('.') || (e.wire ? e.wire.join(' → ') : '')}</span>
            <span className="p-msg">{e.message}</span>
          </button>
        ))
      )}
    </div>
  );
}

// ---------------------------------------------------------------- run

export function RunResults({ status, fileUrl, hasRun }: { status: RunStatus | null; fileUrl: (u: string) => string; hasRun: boolean }) {
  if (!status) return <div className="muted pad">Press Run to simulate what you drew. After a run, click a wire to plot its signal.</div>;
  const err = status.error ? (typeof status.error === 'string' ? status.error : status.error.message) : null;
  return (
    <div className="run-results">
      <div className={`run-state ${status.status}`}>
        {status.status}
        {status.status === 'running' ? ` ${Math.round(100 * status.progress)} %` : ''}
      </div>
      {status.outcome ? (
        <div className="outcome" data-testid="outcome">
          {status.outcome}
        </div>
      ) : null}
      {err ? <div className="insp-error">{err}</div> : null}
      {hasRun && status.status === 'done' ? <div className="muted small pad-b">Click a wire to plot its signal.</div> : null}
      {(status.figures ?? []).map((f) => (
        <figure key={f.name} className="figure">
          <a href={fileUrl(f.url)} target="_blank" rel="noreferrer">
            <img src={fileUrl(f.url)} alt={f.name} />
          </a>
          <figcaption>{f.name}</figcaption>
        </figure>
      ))}
    </div>
  );
}

const COLORS = ['#2563eb', '#dc2626', '#16a34a', '#9333ea', '#ea580c', '#0891b2', '#ca8a04', '#db2777'];

function ticks(lo: number, hi: number, n = 4): number[] {
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

/** A small line plot of a logged signal against time. */
export function SignalPlot({ name, data, onClose }: { name: string; data: SignalData | null; onClose: () => void }) {
  const [agent, setAgent] = useState(0);
  const W = 440;
  const H = 220;
  const m = { l: 48, r: 10, t: 10, b: 28 };
  const nAgents = data && Array.isArray(data.values[0]) && Array.isArray((data.values[0] as unknown[])[0]) ? (data.values[0] as unknown[]).length : 0;
  let body: ReactNode = <div className="muted pad">Loading {name}…</div>;
  let legend: { label: string; color: string }[] = [];
  if (data && data.t.length) {
    const lines = signalLines(data, Math.min(agent, Math.max(0, nAgents - 1)));
    legend = lines.map((l, j) => ({ label: l.label, color: COLORS[j % COLORS.length] }));
    const t0 = data.t[0];
    const t1 = data.t[data.t.length - 1];
    let lo = Infinity;
    let hi = -Infinity;
    for (const l of lines) for (const y of l.ys) if (Number.isFinite(y)) ((lo = Math.min(lo, y)), (hi = Math.max(hi, y)));
    if (!Number.isFinite(lo)) ((lo = 0), (hi = 1));
    if (!(hi > lo)) ((lo -= 1), (hi += 1));
    const pad = 0.05 * (hi - lo);
    lo -= pad;
    hi += pad;
    const x = (t: number) => m.l + ((t - t0) / (t1 - t0 || 1)) * (W - m.l - m.r);
    const y = (v: number) => H - m.b - ((v - lo) / (hi - lo)) * (H - m.t - m.b);
    body = (
      <svg width={W} height={H} className="plot" data-testid="signal-plot">
        {ticks(lo, hi).map((v) => (
          <g key={`y${v}`}>
            <line x1={m.l} x2={W - m.r} y1={y(v)} y2={y(v)} className="grid" />
            <text x={m.l - 6} y={y(v) + 4} textAnchor="end">
              {+v.toPrecision(4)}
            </text>
          </g>
        ))}
        {ticks(t0, t1).map((v) => (
          <text key={`x${v}`} x={x(v)} y={H - 10} textAnchor="middle">
            {+v.toPrecision(4)}
          </text>
        ))}
        <text x={W - m.r} y={H - 10} textAnchor="end">t [s]</text>
        <line x1={m.l} x2={m.l} y1={m.t} y2={H - m.b} className="axis" />
        <line x1={m.l} x2={W - m.r} y1={H - m.b} y2={H - m.b} className="axis" />
        {lines.map((l, j) => (
          <path
            key={j}
            d={l.ys.map((v, i) => `${i ? 'L' : 'M'}${x(data.t[i]).toFixed(1)},${y(Number.isFinite(v) ? v : lo).toFixed(1)}`).join('')}
            stroke={COLORS[j % COLORS.length]}
            fill="none"
            strokeWidth={1.5}
          >
            <title>{l.label}</title>
          </path>
        ))}
      </svg>
    );
  } else if (data) body = <div className="muted pad">No samples.</div>;
  return (
    <div className="plot-panel">
      <div className="plot-head">
        <span className="mono">{name}</span>
        {data?.shape ? <span className="muted small"> ({Array.isArray(data.shape) ? data.shape.join(', ') : data.shape})</span> : null}
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

// ---------------------------------------------------------------- dialogs

export function Modal({ title, children, onClose }: { title: string; children: ReactNode; onClose: () => void }) {
  const ref = useRef<HTMLDivElement>(null);
  useEffect(() => {
    ref.current?.querySelector<HTMLElement>('input, button, select, textarea')?.focus();
  }, []);
  return (
    <div
      className="modal-bg"
      onMouseDown={(e) => {
        if (e.target === e.currentTarget) onClose();
      }}
      onKeyDown={(e) => {
        if (e.key === 'Escape') {
          e.stopPropagation();
          onClose();
        }
      }}
    >
      <div className="modal" role="dialog" aria-label={title} ref={ref}>
        <div className="modal-head">
          <span>{title}</span>
          <button className="link" onClick={onClose} aria-label="Close">
            ×
          </button>
        </div>
        <div className="modal-body">{children}</div>
      </div>
    </div>
  );
}

export function FilesDialog({ files, onOpen, onClose }: { files: FileList | null; onOpen: (a: { path?: string; builtin?: string }) => void; onClose: () => void }) {
  const [q, setQ] = useState('');
  const f = (s: string) => s.toLowerCase().includes(q.toLowerCase());
  return (
    <Modal title="Open a diagram" onClose={onClose}>
      <input type="search" placeholder="Filter" value={q} onChange={(e) => setQ(e.target.value)} className="wide" />
      {!files ? <div className="muted pad">Loading…</div> : null}
      {files ? (
        <div className="file-cols">
          <div>
            <div className="insp-section">Files in {files.root}</div>
            {files.files.filter((x) => f(x.path)).map((x) => (
              <button key={x.path} className="file-item" data-file={x.path} onClick={() => onOpen({ path: x.path })}>
                {x.path}
              </button>
            ))}
            {!files.files.length ? <div className="muted small">No scenario files here yet.</div> : null}
          </div>
          <div>
            <div className="insp-section">Built-in case studies</div>
            {files.builtins.filter((x) => f(x.name)).map((x) => (
              <button key={x.name} className="file-item" data-builtin={x.name} onClick={() => onOpen({ builtin: x.name })}>
                {x.name} {x.kind ? <span className="muted small">{x.kind}</span> : null}
                {x.editable === false ? <span className="muted small"> (view only)</span> : null}
              </button>
            ))}
          </div>
        </div>
      ) : null}
    </Modal>
  );
}

export const SHORTCUTS: [string, string][] = [
  ['Ctrl+Z', 'undo'],
  ['Ctrl+Shift+Z / Ctrl+Y', 'redo'],
  ['Ctrl+C / Ctrl+V', 'copy / paste the selection'],
  ['Ctrl+X', 'cut'],
  ['Ctrl+D', 'duplicate'],
  ['Delete / Backspace', 'delete the selection'],
  ['Ctrl+A', 'select all'],
  ['Ctrl+G', 'group the selection into a subsystem'],
  ['Ctrl+Shift+G', 'ungroup'],
  ['Enter (on a subsystem)', 'open it'],
  ['Escape', 'leave the subsystem / clear the selection'],
  ['Ctrl+S / Ctrl+Shift+S', 'save / save as'],
  ['Ctrl+O', 'open'],
  ['Ctrl+Enter', 'run'],
  ['/ or Ctrl+K', 'search the palette (Enter adds)'],
  ['L', 'automatic layout'],
  ['F', 'fit the view'],
  ['?', 'this help'],
  ['drag / wheel', 'pan / zoom; Shift+drag selects a box'],
];

export function HelpOverlay({ onClose }: { onClose: () => void }) {
  return (
    <Modal title="Keyboard shortcuts" onClose={onClose}>
      <table className="keys">
        <tbody>
          {SHORTCUTS.map(([k, v]) => (
            <tr key={k}>
              <td>
                {k.split(' / ').map((x, i) => (
                  <span key={i}>
                    {i ? ' / ' : ''}
                    <kbd>{x}</kbd>
                  </span>
                ))}
              </td>
              <td>{v}</td>
            </tr>
          ))}
        </tbody>
      </table>
      <p className="muted small">
        Draw a wire from an output (right side of a block) to an input (left side). An input has one driver: a new wire into a taken input replaces the old one.
      </p>
    </Modal>
  );
}
