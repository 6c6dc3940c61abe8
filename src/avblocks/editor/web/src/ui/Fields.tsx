// Value fields: what is typed is read as data and given to the library, which judges it (the
// check answers with an error on the field, in its own words). The page reads the text only
// (numbers, [lists], {mappings}, $references, words); text it cannot read is not dropped: the
// field says so and the diagram counts it as a problem until it is fixed (FieldStatus).

import { createContext, useContext, useEffect, useMemo, useRef, useState } from 'react';
import type { ReactNode } from 'react';
import type { GeneratorDecl, Json, ParamDecl } from '../types';
import { generatorOf, ModelError, parseValue, valueToText } from '../model';
import { plainText } from './Text';

/** Fields holding text that is not applied (it could not be read), by field key. */
export interface FieldStatus {
  set(key: string, message: string | null): void;
}

export const FieldStatusContext = createContext<FieldStatus>({ set: () => {} });

function jsonEq(a: unknown, b: unknown): boolean {
  if (typeof a === 'number' && typeof b === 'number') return Object.is(a, b) || a === b;
  return valueToText(a as Json) === valueToText(b as Json) && typeof a === typeof b;
}

/** A message about a document entry, without the entry's own name in front (the field is it). */
export function onField(message: string, field?: string | null): string {
  if (field && message.startsWith(`${field}: `)) return message.slice(field.length + 2);
  return message;
}

/** A text field holding one value; commits parsed values. `field` names it for FieldStatus. */
export function ValueField({
  value,
  onCommit,
  multiline = false,
  placeholder,
  refs,
  testid,
  field,
  errors = [],
}: {
  value: Json | undefined;
  onCommit: (v: Json | undefined) => void;
  multiline?: boolean;
  placeholder?: string;
  refs: string[];
  testid?: string;
  field?: string;
  errors?: string[];
}) {
  const [text, setText] = useState(valueToText(value));
  const [err, setErr] = useState<string | null>(null);
  const status = useContext(FieldStatusContext);
  const key = useRef(field);
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
      if (field) status.set(field, null);
    }
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [value]);
  // a field that goes away takes its unread text with it
  useEffect(() => {
    key.current = field;
    return () => {
      if (key.current) status.set(key.current, null);
    };
  }, [field, status]);
  const listId = useMemo(() => `refs-${Math.random().toString(36).slice(2)}`, []);
  const change = (t: string) => {
    setText(t);
    if (t.trim() === '') {
      setErr(null);
      if (field) status.set(field, null);
      onCommit(undefined);
      return;
    }
    let v: Json;
    try {
      v = parseValue(t);
    } catch (e) {
      const msg = `not applied: ${e instanceof ModelError ? e.message : String(e)}`;
      setErr(msg);
      if (field) status.set(field, msg);
      return;
    }
    setErr(null);
    if (field) status.set(field, null);
    onCommit(v);
  };
  const shown = [...(err ? [err] : []), ...errors.map((e) => onField(e, field))];
  const props = {
    value: text,
    placeholder,
    className: `vf ${shown.length ? 'bad' : ''}`,
    spellCheck: false,
    'data-testid': testid,
    'aria-invalid': shown.length > 0,
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
      {shown.map((m, i) => (
        <div key={i} className="vf-err" data-testid={testid ? `${testid}-error` : undefined}>
          {m}
        </div>
      ))}
    </div>
  );
}

function GeneratorField({
  value,
  onCommit,
  generators,
  refs,
  param,
  field,
}: {
  value: Json | undefined;
  onCommit: (v: Json | undefined) => void;
  generators: GeneratorDecl[];
  refs: string[];
  param: string;
  field: string;
}) {
  const names = generators.map((g) => g.name);
  const gen = generatorOf(value, names);
  const mode = value === undefined ? '' : gen ? gen.name : typeof value === 'string' && value.startsWith('$') ? '$' : 'literal';
  const setMode = (m: string) => {
    if (m === '') onCommit(undefined);
    else if (m === 'literal') onCommit(gen ? [] : (value ?? []));
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
                field={`${field}.${gen.name}.${a.name}`}
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
        <ValueField value={value} refs={refs} onCommit={onCommit} multiline={mode === 'literal'} field={field} />
      ) : null}
    </div>
  );
}

/** One block parameter: a control chosen by its declared kind, and the check's errors on it. */
export function ParamField({
  decl,
  value,
  onCommit,
  refs,
  generators,
  errors,
  field,
}: {
  decl: ParamDecl;
  value: Json | undefined;
  onCommit: (v: Json | undefined) => void;
  refs: string[];
  generators: GeneratorDecl[];
  errors: string[];
  field: string;
}) {
  const k = decl.kind;
  const isRef = typeof value === 'string' && value.startsWith('$');
  const def = decl.default !== null && decl.default !== undefined ? valueToText(decl.default) : '';
  const shown = errors.map((e) => onField(e, field));
  let field_: ReactNode;
  let errorsBelow = true;
  if (k === 'bool' && !isRef) {
    const cur = value === undefined ? decl.default === true : value === true;
    field_ = <input type="checkbox" checked={cur} onChange={(e) => onCommit(e.target.checked)} data-testid={`param-${decl.name}`} />;
  } else if (k === 'choice' && decl.choices && !isRef) {
    field_ = (
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
    field_ = <GeneratorField value={value} onCommit={onCommit} generators={generators} refs={refs} param={decl.name} field={field} />;
  } else {
    const multi = !['float', 'int', 'str', 'bool', 'choice'].includes(k);
    errorsBelow = false;
    field_ = (
      <ValueField
        value={value}
        onCommit={onCommit}
        multiline={multi && (value === undefined ? false : valueToText(value).length > 30)}
        placeholder={def || (decl.required ? 'required' : '')}
        refs={refs}
        testid={`param-${decl.name}`}
        field={field}
        errors={errors}
      />
    );
  }
  const b = decl.bounds;
  const range = b && (b[0] !== null || b[1] !== null) ? `${b[0] ?? '−∞'} … ${b[1] ?? '∞'}` : '';
  return (
    <div className={`param ${errors.length ? 'bad' : ''}`} data-param={decl.name} data-field={field}>
      <div className="param-head" title={plainText(decl.doc)}>
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
      {field_}
      {errorsBelow
        ? shown.map((e, i) => (
            <div key={i} className="vf-err" data-testid={`param-${decl.name}-error`}>
              {e}
            </div>
          ))
        : null}
    </div>
  );
}
