// The palette: every block by family; a search ranks them (search.ts); a hovered block's card.

import { useEffect, useMemo, useState } from 'react';
import type { BlockDecl, Palette } from '../types';
import { declOf, valueToText } from '../model';
import { search } from '../search';
import { plainText, Rich } from './Text';

export const DRAG_MIME = 'application/x-avblocks-type';

function Item({ b, family, cursor, shown, onAdd, onShow }: { b: BlockDecl; family: string; cursor: boolean; shown: boolean; onAdd: (t: string) => void; onShow: (t: string | null) => void }) {
  return (
    <div
      className={`palette-item fam-${family} ${cursor ? 'cursor' : ''} ${shown ? 'shown' : ''}`}
      draggable
      tabIndex={0}
      data-type={b.type}
      onDragStart={(e) => {
        e.dataTransfer.setData(DRAG_MIME, b.type);
        e.dataTransfer.setData('text/plain', b.type);
        e.dataTransfer.effectAllowed = 'copy';
      }}
      onMouseEnter={() => onShow(b.type)}
      onMouseLeave={() => onShow(null)}
      onFocus={() => onShow(b.type)}
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
      <div className="pi-summary" title={plainText(b.summary)}>
        <Rich text={b.summary} />
      </div>
    </div>
  );
}

export function PalettePanel({ palette, onAdd, searchRef }: { palette: Palette | null; onAdd: (type: string) => void; searchRef: React.RefObject<HTMLInputElement | null> }) {
  const [q, setQ] = useState('');
  const [shown, setShown] = useState<string | null>(null);
  const [open, setOpen] = useState<Record<string, boolean>>({});
  const [cursor, setCursor] = useState(0);
  const familyOf = useMemo(() => {
    const m = new Map<string, string>();
    for (const f of palette?.families ?? []) for (const b of f.blocks) m.set(b.type, f.name);
    return m;
  }, [palette]);
  const all = useMemo(() => (palette ? palette.families.flatMap((f) => f.blocks) : []), [palette]);
  const found = useMemo(() => (q.trim() ? search(all, q) : []), [all, q]);
  useEffect(() => setCursor(0), [q]);
  if (!palette) return <div className="palette"><div className="muted pad">Loading the palette…</div></div>;
  const detail = shown ? declOf(palette, shown) : q && found[cursor] ? found[cursor] : null;
  const add = (t: string) => onAdd(t);
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
      <div className="palette-list" data-testid="palette-list">
        {q.trim() ? (
          <div className="family" data-testid="search-results">
            <div className="family-head static">
              Best matches <span className="count">{found.length}</span>
            </div>
            {found.map((b, i) => (
              <Item key={b.type} b={b} family={familyOf.get(b.type) ?? 'other'} cursor={i === cursor} shown={shown === b.type} onAdd={add} onShow={setShown} />
            ))}
            {!found.length ? <div className="muted pad">No block matches “{q}”.</div> : null}
          </div>
        ) : (
          palette.families.map((f) => {
            const isOpen = open[f.name] ?? true;
            return (
              <div key={f.name} className={`family fam-${f.name}`}>
                <button className="family-head" onClick={() => setOpen({ ...open, [f.name]: !isOpen })}>
                  <span className="caret">{isOpen ? '▾' : '▸'}</span> {f.title} <span className="count">{f.blocks.length}</span>
                </button>
                {isOpen ? f.blocks.map((b) => <Item key={b.type} b={b} family={f.name} cursor={false} shown={shown === b.type} onAdd={add} onShow={setShown} />) : null}
              </div>
            );
          })
        )}
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
          <tr key={`${p.dir}-${p.name}`} title={plainText(p.doc)}>
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
      {decl.summary ? (
        <div className="bc-summary">
          <Rich text={decl.summary} />
        </div>
      ) : null}
      <PortTable decl={decl} />
      {decl.params.length ? (
        <div className="bc-params">
          {decl.params.map((p) => (
            <div key={p.name} className="bc-param" title={plainText(p.doc)}>
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
