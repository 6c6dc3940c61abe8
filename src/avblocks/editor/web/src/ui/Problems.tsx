// The problems the check found (and text typed that could not be read), each a link to what
// it is about.

import type { ValidationError } from '../types';
import { onField } from './Fields';

/** Where a problem is, as the list names it. */
export function where(e: ValidationError): string {
  if (e.field) return e.field.replace(/^blocks\./, '');
  return [e.block, e.port ?? e.param].filter(Boolean).join('.') || (e.wire ? e.wire.join(' → ') : '');
}

export function ProblemList({ errors, onPick }: { errors: ValidationError[]; onPick: (e: ValidationError) => void }) {
  return (
    <>
      {errors.map((e, i) => (
        <button key={i} className="problem" onClick={() => onPick(e)} title="Show it" data-testid="problem">
          <span className="p-kind">{e.kind ?? 'Error'}</span>
          <span className="p-where mono">{where(e)}</span>
          <span className="p-msg">{onField(e.message, e.field)}</span>
        </button>
      ))}
    </>
  );
}

export function ProblemsPanel({ errors, onPick, validating }: { errors: ValidationError[]; onPick: (e: ValidationError) => void; validating: boolean }) {
  return (
    <div className="problems" data-testid="problems">
      {errors.length === 0 ? <div className="muted pad">{validating ? 'Checking…' : 'No problems: the diagram builds.'}</div> : <ProblemList errors={errors} onPick={onPick} />}
    </div>
  );
}
