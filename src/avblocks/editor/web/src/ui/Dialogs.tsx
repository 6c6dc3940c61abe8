// Dialogs, in plain words: open, save as, a file changed on disk or already there, saving a
// file that runs as a draft that does not, the keyboard shortcuts, an export.

import { useEffect, useRef, useState } from 'react';
import type { ReactNode } from 'react';
import type { FileList } from '../types';

export function Modal({ title, children, onClose }: { title: string; children: ReactNode; onClose: () => void }) {
  const ref = useRef<HTMLDivElement>(null);
  useEffect(() => {
    ref.current?.querySelector<HTMLElement>('input, button.primary, button, select, textarea')?.focus();
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

export function SaveAs({ initial, draft, onSave, onClose }: { initial: string; draft: boolean; onSave: (p: string) => void; onClose: () => void }) {
  const [p, setP] = useState(initial);
  const ok = /\.(ya?ml)$/.test(p) && !p.startsWith('/') && !p.split('/').includes('..');
  return (
    <Modal title="Save as" onClose={onClose}>
      <label className="row col">
        <span>file name (in the editor's folder, ending in .yaml)</span>
        <input
          className="wide"
          value={p}
          onChange={(e) => setP(e.target.value)}
          aria-label="File path"
          onKeyDown={(e) => {
            if (e.key === 'Enter' && ok) onSave(p);
          }}
        />
      </label>
      <p className="muted small">The diagram takes the file's name (it names the run's output folder).</p>
      {draft ? <p className="warn small">The diagram has problems: it is saved as a draft, as drawn; avblocks run will list the same problems.</p> : null}
      <div className="row">
        <button className="primary" disabled={!ok} onClick={() => onSave(p)} data-testid="saveas-ok">
          Save
        </button>
        <button onClick={onClose}>Cancel</button>
      </div>
    </Modal>
  );
}

/** A save that would replace a file: changed on disk since it was opened, or another file. */
export function ConflictDialog({ path, exists, onOverwrite, onReload, onSaveAs, onClose }: { path: string; exists: boolean; onOverwrite: () => void; onReload: () => void; onSaveAs: () => void; onClose: () => void }) {
  return (
    <Modal title={exists ? 'A file with that name exists' : 'The file changed on disk'} onClose={onClose}>
      <p>
        <span className="mono">{path}</span>{' '}
        {exists ? 'is already there: it is another file than the one you opened.' : 'was changed by another program after you opened it here.'}
      </p>
      <div className="col-buttons">
        <button className="danger" onClick={onOverwrite} data-testid="overwrite">
          {exists ? 'Replace that file with this diagram' : 'Save my diagram over it (its changes are lost)'}
        </button>
        {!exists ? (
          <button onClick={onReload} data-testid="reload">
            Open the file as it is now (my changes are lost)
          </button>
        ) : null}
        <button onClick={onSaveAs}>Save my diagram under another name…</button>
        <button onClick={onClose}>Cancel</button>
      </div>
    </Modal>
  );
}

/** Ctrl+S on a file that runs, after edits that made the diagram invalid. */
export function DraftGuard({ path, problems, onDraft, onSaveAs, onShow, onClose }: { path: string; problems: number; onDraft: () => void; onSaveAs: () => void; onShow: () => void; onClose: () => void }) {
  return (
    <Modal title="Save it with problems?" onClose={onClose}>
      <p>
        <span className="mono">{path}</span> runs as it is on disk. With your changes the diagram has {problems === 1 ? 'a problem' : `${problems} problems`}: saving now writes a
        draft over it, which <span className="mono">avblocks run</span> will refuse until {problems === 1 ? 'it is' : 'they are'} fixed.
      </p>
      <div className="col-buttons">
        <button className="primary" onClick={onShow} data-testid="guard-show">
          Show the problems (do not save)
        </button>
        <button onClick={onSaveAs} data-testid="guard-saveas">
          Save the draft under another name…
        </button>
        <button className="danger" onClick={onDraft} data-testid="guard-draft">
          Save the draft over {path}
        </button>
      </div>
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
  ['F / Shift+F', 'fit the view / zoom to the selection'],
  ['?', 'this help'],
  ['drag / wheel', 'pan / zoom; Shift+drag selects a box'],
  ['click / Shift+click a wire', 'after a run: plot its signal / add it to the plot'],
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
        Draw a wire from an output (right side of a block) to an input (left side). An input has one driver: a new wire into a taken input replaces the old one. Hover a port to light every wire of
        its signal.
      </p>
    </Modal>
  );
}

export function ExportDialog({ text, filename, onDownload, onCopy, onClose }: { text: string; filename: string; onDownload: () => void; onCopy: () => void; onClose: () => void }) {
  return (
    <Modal title={`Export: ${filename}`} onClose={onClose}>
      <pre className="code">{text}</pre>
      <div className="row">
        <button className="primary" onClick={onDownload}>
          Download
        </button>
        <button onClick={onCopy}>Copy</button>
      </div>
    </Modal>
  );
}
