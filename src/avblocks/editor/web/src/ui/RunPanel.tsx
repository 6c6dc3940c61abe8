// The Run tab: where the run stands, its outcome line and figures; a run refused for problems
// lists them, each a link to what it is about.

import type { RunStatus, ValidationError } from '../types';
import { ProblemList } from './Problems';

export function RunResults({
  status,
  fileUrl,
  hasRun,
  refused,
  onPick,
}: {
  status: RunStatus | null;
  fileUrl: (u: string) => string;
  hasRun: boolean;
  refused: ValidationError[] | null;
  onPick: (e: ValidationError) => void;
}) {
  if (refused && refused.length)
    return (
      <div className="run-results" data-testid="run-refused">
        <div className="run-state failed">not run</div>
        <p className="small">
          The diagram does not run yet: {refused.length === 1 ? 'fix this problem' : `fix these ${refused.length} problems`} first (click one to go to it).
        </p>
        <ProblemList errors={refused} onPick={onPick} />
      </div>
    );
  if (!status) return <div className="muted pad">Press Run to simulate what you drew. After a run, click a wire to plot its signal.</div>;
  const err = status.error ? (typeof status.error === 'string' ? status.error : status.error.message) : null;
  const partial = status.status === 'cancelled' && (status.signals ?? []).length > 0;
  return (
    <div className="run-results">
      <div className={`run-state ${status.status}`} data-testid="run-state" data-run={status.run ?? ''}>
        {status.status === 'cancelled' ? 'stopped' : status.status}
        {status.status === 'running' ? ` ${Math.round(100 * status.progress)} %` : ''}
        {status.status === 'cancelled' && status.t !== undefined ? ` at t = ${+status.t.toPrecision(6)} s` : ''}
      </div>
      {status.outcome ? (
        <div className="outcome" data-testid="outcome">
          {status.outcome}
        </div>
      ) : null}
      {err ? <div className="insp-error">{err}</div> : null}
      {hasRun && (status.status === 'done' || partial) ? (
        <div className="muted small pad-b">
          {partial ? 'What was computed until the stop is kept: ' : ''}click a wire to plot its signal (Shift+click adds it to the plot).
        </div>
      ) : null}
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
