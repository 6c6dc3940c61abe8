// Edits made on the canvas: blocks moved, selected, added, deleted, copied and pasted, wires
// drawn, groups made and opened, the automatic layout. Each edit is a function of the
// document model (model.ts) committed to the undo history.

import { useCallback, useRef } from 'react';
import type { Dispatch, MutableRefObject, SetStateAction } from 'react';
import type { Connection, Edge, EdgeChange, NodeChange, ReactFlowInstance } from '@xyflow/react';
import type { Doc, Palette, XY } from '../types';
import * as M from '../model';
import { handleRef, IN_NODE, OUT_NODE } from '../flow';
import type { FlowEdge, FlowNode } from '../flow';
import { layoutLevel } from '../layout';
import { DRAG_MIME } from '../ui/Palette';

type Set_<T> = Dispatch<SetStateAction<T>>;

export function useEdits({
  doc,
  setHist,
  edit,
  palette,
  level,
  path,
  setPath,
  flow,
  selected,
  setSelected,
  selectedEdges,
  setSelectedEdges,
  toast,
  rf,
  moveSoon,
  fitRef,
  onAdded,
}: {
  doc: Doc;
  setHist: Set_<M.History>;
  edit: (f: (d: Doc) => Doc, key?: string | null) => void;
  palette: Palette | null;
  level: string | null;
  path: string[];
  setPath: Set_<string[]>;
  flow: { nodes: FlowNode[]; edges: FlowEdge[] };
  selected: Set<string>;
  setSelected: Set_<Set<string>>;
  selectedEdges: Set<string>;
  setSelectedEdges: Set_<Set<string>>;
  toast: (t: string, k?: 'info' | 'warn' | 'error') => void;
  rf: ReactFlowInstance;
  moveSoon: (move: () => void) => void;
  fitRef: MutableRefObject<(duration?: number) => void>;
  onAdded: () => void;
}) {
  const clipboard = useRef<M.Fragment | null>(null);
  const pasteCount = useRef(0);
  const dragStart = useRef(false);

  const onNodesChange = useCallback(
    (changes: NodeChange[]) => {
      const moves: Record<string, XY> = {};
      let sel: Set<string> | null = null;
      for (const c of changes) {
        if (c.type === 'position' && c.position && c.id !== IN_NODE && c.id !== OUT_NODE) moves[c.id] = [c.position.x, c.position.y];
        if (c.type === 'select') {
          sel = sel ?? new Set(selected);
          if (c.selected) sel.add(c.id);
          else sel.delete(c.id);
        }
      }
      if (Object.keys(moves).length) {
        setHist((h) => {
          const d = M.moveItems(h.present, moves);
          if (dragStart.current) {
            dragStart.current = false;
            return M.commit(h, d);
          }
          return M.replace(h, d);
        });
      }
      if (sel) setSelected(sel);
    },
    [selected, setHist, setSelected],
  );

  const onEdgesChange = useCallback(
    (changes: EdgeChange[]) => {
      let sel: Set<string> | null = null;
      for (const c of changes) {
        if (c.type === 'select') {
          sel = sel ?? new Set(selectedEdges);
          if (c.selected) sel.add(c.id);
          else sel.delete(c.id);
        }
      }
      if (sel) setSelectedEdges(sel);
    },
    [selectedEdges, setSelectedEdges],
  );

  const onConnect = useCallback(
    (c: Connection) => {
      if (!c.source || !c.target || !c.sourceHandle || !c.targetHandle) return;
      if (c.target === OUT_NODE) {
        toast('to feed something outside this subsystem, leave it (Escape) and draw the wire there', 'warn');
        return;
      }
      const from = handleRef(doc, c.source, c.sourceHandle);
      const to = handleRef(doc, c.target, c.targetHandle);
      try {
        const r = M.connect(doc, from, to);
        if (!r.added) return;
        setHist((h) => M.commit(h, r.doc));
        if (r.replaced) toast(`${to} had a driver (${r.replaced[0]}): an input has one driver, so the new wire from ${from} replaces it`, 'warn');
      } catch (e) {
        toast((e as Error).message, 'warn');
      }
    },
    [doc, toast, setHist],
  );

  const isValidConnection = useCallback((c: Connection | Edge) => c.target !== OUT_NODE && c.source !== OUT_NODE && c.target !== IN_NODE, []);

  const addAt = useCallback(
    (type: string, pos?: XY) => {
      const decl = M.declOf(palette, type);
      let p = pos;
      if (!p) {
        const el = document.querySelector('.canvas');
        const r = el?.getBoundingClientRect();
        const c = rf.screenToFlowPosition({ x: (r?.left ?? 0) + (r?.width ?? 800) / 2, y: (r?.top ?? 0) + (r?.height ?? 600) / 2 });
        // the centre of the view, or the nearest free spot right of / below it
        const boxes = flow.nodes.map((n) => [n.position.x, n.position.y, n.position.x + (n.width ?? 210), n.position.y + (n.height ?? 80)]);
        const free = (x: number, y: number) => !boxes.some((b) => x < b[2] + 30 && b[0] < x + 240 && y < b[3] + 30 && b[1] < y + 110);
        const x0 = c.x - 105;
        const y0 = c.y - 40;
        p = [x0, y0];
        search: for (let row = 0; row < 8; row++)
          for (let col = 0; col < 4; col++)
            if (free(x0 + col * 270, y0 + row * 130)) {
              p = [x0 + col * 270, y0 + row * 130];
              break search;
            }
      }
      try {
        const r = M.addBlock(doc, type, { template: decl?.template ?? {}, position: p });
        let d = r.doc;
        if (level !== null) d = { ...d, editor: { ...d.editor, groups: { ...d.editor!.groups, [level]: { ...d.editor!.groups![level], blocks: [...d.editor!.groups![level].blocks, r.name] } } } };
        setHist((h) => M.commit(h, d));
        setSelected(new Set([r.name]));
        setSelectedEdges(new Set());
        onAdded();
      } catch (e) {
        toast((e as Error).message, 'warn');
      }
    },
    [doc, level, palette, rf, toast, flow.nodes, setHist, setSelected, setSelectedEdges, onAdded],
  );

  const onDrop = useCallback(
    (e: React.DragEvent) => {
      e.preventDefault();
      const type = e.dataTransfer.getData(DRAG_MIME) || e.dataTransfer.getData('text/plain');
      if (!type) return;
      const p = rf.screenToFlowPosition({ x: e.clientX, y: e.clientY });
      addAt(type, [p.x - 20, p.y - 15]);
    },
    [addAt, rf],
  );

  const deleteSelection = useCallback(() => {
    const items = [...selected].filter((n) => n !== IN_NODE && n !== OUT_NODE);
    const wires = flow.edges.filter((e) => selectedEdges.has(e.id)).map((e) => e.data.wire);
    if (!items.length && !wires.length) return;
    edit((d) => {
      let x = M.removeItems(d, items);
      for (const w of wires) x = M.disconnect(x, w);
      return x;
    });
    setSelected(new Set());
    setSelectedEdges(new Set());
  }, [selected, selectedEdges, flow.edges, edit, setSelected, setSelectedEdges]);

  const copy = useCallback(() => {
    const items = [...selected].filter((n) => n !== IN_NODE && n !== OUT_NODE);
    if (!items.length) return false;
    clipboard.current = M.copyItems(doc, items);
    pasteCount.current = 0;
    toast(`copied ${Object.keys(clipboard.current.blocks).length} block(s)`);
    return true;
  }, [doc, selected, toast]);

  const paste = useCallback(() => {
    if (!clipboard.current) return;
    pasteCount.current += 1;
    const off = 40 * pasteCount.current;
    const r = M.paste(doc, clipboard.current, [off, off], level);
    setHist((h) => M.commit(h, r.doc));
    setSelected(new Set(r.names));
  }, [doc, level, setHist, setSelected]);

  const group = useCallback(() => {
    const items = [...selected].filter((n) => n !== IN_NODE && n !== OUT_NODE);
    if (!items.length) return toast('select blocks to group (Shift+drag draws a selection box)', 'warn');
    try {
      const r = M.groupItems(doc, items);
      setHist((h) => M.commit(h, r.doc));
      setSelected(new Set([r.name]));
      toast(`grouped ${items.length} item(s) into ${r.name}; double-click it to open`);
    } catch (e) {
      toast((e as Error).message, 'warn');
    }
  }, [doc, selected, toast, setHist, setSelected]);

  const ungroup = useCallback(() => {
    const gs = [...selected].filter((n) => n in (doc.editor?.groups ?? {}));
    if (!gs.length) return;
    edit((d) => gs.reduce((x, g) => M.ungroup(x, g), d));
    setSelected(new Set(gs.flatMap((g) => [...(doc.editor!.groups![g].blocks ?? []), ...(doc.editor!.groups![g].groups ?? [])])));
  }, [doc, selected, edit, setSelected]);

  const autoLayout = useCallback(async () => {
    const pos = await layoutLevel(doc, palette, level);
    setHist((h) => M.commit(h, M.moveItems(h.present, pos)));
    moveSoon(() => fitRef.current(200));
  }, [doc, palette, level, moveSoon, fitRef, setHist]);

  const openGroup = useCallback(
    (g: string) => {
      setPath((p) => [...p, g]);
      setSelected(new Set());
      setSelectedEdges(new Set());
      moveSoon(() => fitRef.current(150));
    },
    [moveSoon, fitRef, setPath, setSelected, setSelectedEdges],
  );

  const leaveTo = useCallback(
    (depth: number) => {
      setPath((p) => p.slice(0, depth));
      setSelected(new Set());
      moveSoon(() => fitRef.current(150));
    },
    [moveSoon, fitRef, setPath, setSelected],
  );

  return {
    onNodesChange,
    onEdgesChange,
    onConnect,
    isValidConnection,
    onNodeDragStart: () => {
      dragStart.current = true;
    },
    addAt,
    onDrop,
    deleteSelection,
    copy,
    paste,
    duplicate: () => {
      if (copy()) paste();
    },
    cut: () => {
      if (copy()) deleteSelection();
    },
    group,
    ungroup,
    autoLayout,
    openGroup,
    leaveTo,
    selectAll: () => setSelected(new Set(flow.nodes.filter((n) => n.type !== 'boundary').map((n) => n.id))),
    escape: () => {
      if (selected.size || selectedEdges.size) {
        setSelected(new Set());
        setSelectedEdges(new Set());
      } else if (path.length) leaveTo(path.length - 1);
    },
    enter: () => {
      if (selected.size !== 1) return false;
      const [s] = [...selected];
      if (!(s in (doc.editor?.groups ?? {}))) return false;
      openGroup(s);
      return true;
    },
  };
}
