// The editor: owns the document (controlled React Flow) and composes the parts, each in a
// module of its own: the toolbar, the palette, the properties, problems, run and tune tabs,
// the plot panel, the dialogs (ui/); keys, view moves and runs (hooks/); the document model
// (model.ts), the flow view (flow.ts), wire routing (router.ts, routes.ts), search (search.ts).

import { useCallback, useEffect, useMemo, useRef, useState } from 'react';
import { Background, Controls, MiniMap, ReactFlow, ReactFlowProvider, useReactFlow, useStore, SelectionMode } from '@xyflow/react';
import type { Connection, EdgeChange, NodeChange, Edge, Node } from '@xyflow/react';
import type { Doc, FileList, Json, Palette, Validation, ValidationError, Wire, XY } from './types';
import * as M from './model';
import { handleRef, IN_NODE, OUT_NODE, routed, stableFlow, toFlow, wireId } from './flow';
import type { FlowEdge, FlowNode } from './flow';
import { layoutAll, layoutLevel, needsLayout } from './layout';
import { Api, ApiError, saveRequest } from './transport';
import type { FileRef, Transport } from './transport';
import { nodeTypes, edgeTypes, HighlightContext, WIRE_CLICK } from './nodes';
import { Highlight } from './highlight';
import { Wiring } from './routes';
import { PalettePanel, DRAG_MIME } from './ui/Palette';
import { FieldStatusContext } from './ui/Fields';
import { BlockPanel, DiagramPanel, GroupPanel, SelectionPanel, WirePanel } from './ui/Inspector';
import { ProblemsPanel } from './ui/Problems';
import { RunResults } from './ui/RunPanel';
import { PlotPanel } from './ui/PlotPanel';
import { TunePanel } from './ui/Tune';
import { Toolbar } from './ui/Toolbar';
import { ConflictDialog, DraftGuard, ExportDialog, FilesDialog, HelpOverlay, SaveAs } from './ui/Dialogs';
import { useKeyboard } from './hooks/useKeyboard';
import { useViewMoves } from './hooks/useViewMoves';
import { useRun } from './hooks/useRun';

interface Toast {
  id: number;
  text: string;
  kind: 'info' | 'warn' | 'error';
}

type Dialog =
  | null
  | { kind: 'open' }
  | { kind: 'saveas'; draft: boolean }
  | { kind: 'conflict'; path: string; draft: boolean; exists?: boolean }
  | { kind: 'guard'; path: string }
  | { kind: 'help' }
  | { kind: 'export'; text: string; filename: string };

type Tab = 'props' | 'problems' | 'run' | 'tune';

/** A node's colour in the minimap (one function for every render: the minimap's nodes stay memoised). */
function miniColor(n: Node): string {
  const f = n as unknown as FlowNode;
  if (f.type === 'subsystem') return '#c7d2fe';
  // red when the block, or one of its ports, has an error (as the block's own mark on the canvas)
  const d = f.data as { errors?: string[]; inputs?: { errors: string[] }[]; outputs?: { errors: string[] }[] } | undefined;
  const bad = !!d && (!!d.errors?.length || [...(d.inputs ?? []), ...(d.outputs ?? [])].some((p) => p.errors.length > 0));
  return bad ? '#f87171' : '#cbd5e1';
}

function download(name: string, href: string) {
  const a = document.createElement('a');
  a.href = href;
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
}

/** The stem of a file path: "dir/my_team.yaml" -> "my_team". */
function stem(p: string): string {
  return (p.split('/').pop() ?? p).replace(/\.(ya?ml)$/, '');
}

/** A toolbar field's text as the value a run gets (empty: none; unreadable: a problem). */
function readOverride(text: string): { value?: Json; error?: string } {
  if (!text.trim()) return {};
  try {
    return { value: M.parseValue(text) };
  } catch (e) {
    return { error: `not applied: ${(e as Error).message}` };
  }
}

function Editor({ transport }: { transport: Transport }) {
  const api = useMemo(() => new Api(transport), [transport]);
  const rf = useReactFlow();
  const view = useViewMoves(rf);
  const highlight = useMemo(() => new Highlight(), []);
  // level of detail: zoomed far out, draw blocks without their text (faster, and unreadable anyway)
  // (one number per zoom band, so panning and zooming within a band render nothing here)
  const detail = useStore((s) => (s.transform[2] < 0.3 ? 2 : s.transform[2] < 0.45 ? 1 : 0));
  const [palette, setPalette] = useState<Palette | null>(null);
  const [hist, setHist] = useState<M.History>(() => M.history(M.emptyDocument()));
  const doc = hist.present;
  const [file, setFile] = useState<FileRef>({ path: null, builtin: null, revision: null });
  const [savedDoc, setSavedDoc] = useState<Doc | null>(doc);
  // whether the file as last loaded or saved runs (its first check, or the save's answer)
  const [savedRuns, setSavedRuns] = useState<boolean | null>(null);
  const [path, setPath] = useState<string[]>([]);
  const level = path.length ? path[path.length - 1] : null;
  const [selected, setSelected] = useState<Set<string>>(new Set());
  const [selectedEdges, setSelectedEdges] = useState<Set<string>>(new Set());
  const [validation, setValidation] = useState<Validation | null>(null);
  const [validating, setValidating] = useState(false);
  // what the last answer was about: the check is fresh when it is the document as it is now
  const [checkedParts, setCheckedParts] = useState<unknown[]>([]);
  const [toasts, setToasts] = useState<Toast[]>([]);
  const [dialog, setDialog] = useState<Dialog>(null);
  const [files, setFiles] = useState<FileList | null>(null);
  const [tab, setTab] = useState<Tab>('props');
  const [backend, setBackend] = useState('numpy');
  const [tFinal, setTFinal] = useState('');
  const [dt, setDt] = useState('');
  const [overrideErrors, setOverrideErrors] = useState<ValidationError[]>([]);
  // fields holding text that could not be read (not applied), by field key
  const [unread, setUnread] = useState<Record<string, string>>({});
  const fieldStatus = useMemo(
    () => ({
      set: (key: string, message: string | null) =>
        setUnread((u) => {
          if ((u[key] ?? null) === message) return u;
          const n = { ...u };
          if (message === null) delete n[key];
          else n[key] = message;
          return n;
        }),
    }),
    [],
  );
  const [tuneAuto, setTuneAuto] = useState(true);
  const [tuneNote, setTuneNote] = useState<string | null>(null);
  const clipboard = useRef<M.Fragment | null>(null);
  const pasteCount = useRef(0);
  const searchRef = useRef<HTMLInputElement>(null);
  const dragStart = useRef(false);
  const toastId = useRef(0);
  const wirings = useRef(new Map<string, Wiring>());

  const toast = useCallback((text: string, kind: Toast['kind'] = 'info') => {
    const id = ++toastId.current;
    setToasts((t) => [...t.slice(-3), { id, text, kind }]);
    setTimeout(() => setToasts((t) => t.filter((x) => x.id !== id)), kind === 'error' ? 7000 : 4000);
  }, []);
  const runs = useRun({ api, toast, highlight });

  const edit = useCallback(
    (f: (d: Doc) => Doc, key: string | null = null) => {
      setHist((h) => {
        try {
          return M.commit(h, f(h.present), key);
        } catch (e) {
          if (e instanceof M.ModelError) setTimeout(() => toast(e.message, 'warn'));
          else throw e;
          return h;
        }
      });
    },
    [toast],
  );

  // ------------------------------------------------------------ the flow view

  // the nodes and edges that did not change keep their objects, so React Flow re-renders
  // only those that did (a block dragged, the wires it moved), not all 500; each level keeps
  // its wiring, which re-routes only the wires near what moved
  const lastFlow = useRef<{ nodes: FlowNode[]; edges: FlowEdge[] }>({ nodes: [], edges: [] });
  const flow = useMemo(() => {
    const key = level ?? '';
    let w = wirings.current.get(key);
    if (!w) wirings.current.set(key, (w = new Wiring()));
    const next = stableFlow(lastFlow.current, routed(toFlow(doc, palette, { level, validation, selected, selectedEdges }), w));
    lastFlow.current = next;
    return next;
  }, [doc, palette, level, validation, selected, selectedEdges]);
  useEffect(() => {
    highlight.setWires(flow.edges.map((e) => ({ id: e.id, source: e.source, sourceHandle: e.sourceHandle, target: e.target, targetHandle: e.targetHandle, signal: e.data.wire[0] })));
  }, [flow.edges, highlight]);

  const fitShown = useCallback(
    (duration = 0, only?: Set<string>) => {
      const nodes = only && only.size ? flow.nodes.filter((n) => only.has(n.id)) : flow.nodes;
      view.fit(nodes.length ? nodes : flow.nodes, flow.edges, duration);
    },
    [flow, view],
  );
  const fitRef = useRef(fitShown);
  fitRef.current = fitShown;

  // ------------------------------------------------------------ loading

  const openDoc = useCallback(
    async (loaded: { document: Doc; path: string | null; builtin: string | null; revision: string | null }, pal: Palette | null) => {
      let d: Doc = { ...loaded.document, blocks: loaded.document.blocks ?? {}, wires: loaded.document.wires ?? [] };
      if (needsLayout(d)) d = await layoutAll(d, pal);
      wirings.current.clear();
      setHist(M.history(d));
      setSavedDoc(d);
      setSavedRuns(null);
      setFile({ path: loaded.path, builtin: loaded.builtin, revision: loaded.revision });
      setPath([]);
      setSelected(new Set());
      setSelectedEdges(new Set());
      runs.reset();
      if (Object.keys(d.blocks).length) view.moveSoon(() => fitRef.current(0));
      else view.moveSoon(() => rf.setViewport({ x: 0, y: 0, zoom: 1 }));
    },
    [rf, view, runs.reset],
  );

  const started = useRef(false);
  useEffect(() => {
    if (started.current) return;
    started.current = true;
    (async () => {
      let pal: Palette | null = null;
      try {
        pal = await api.palette();
        setPalette(pal);
      } catch (e) {
        toast(`palette: ${(e as Error).message}`, 'error');
      }
      try {
        // the file `avblocks edit NAME|FILE` was started with, else a new diagram (GET new)
        const fl = await api.files();
        setFiles(fl);
        if (fl.initial) await openDoc(await api.load(fl.initial), pal);
        else await openDoc(await api.newDocument(), pal);
      } catch (e) {
        toast((e as Error).message, 'error');
      }
    })();
  }, [api, openDoc, toast]);

  const loadFile = useCallback(
    async (a: { path?: string; builtin?: string }) => {
      setDialog(null);
      try {
        const loaded = await api.load(a);
        await openDoc(loaded, palette);
        toast(`opened ${loaded.path ?? loaded.builtin}`);
      } catch (e) {
        toast((e as Error).message, 'error');
      }
    },
    [api, openDoc, palette, toast],
  );

  // ------------------------------------------------------------ validation (debounced)

  const seq = useRef(0);
  useEffect(() => {
    const my = ++seq.current;
    setValidating(true);
    const h = setTimeout(async () => {
      const parts = [doc.blocks, doc.wires, doc.parameters, doc.simulation, doc.params];
      try {
        const v = await api.validate(doc, file.path);
        if (my === seq.current) {
          setValidation(v);
          setCheckedParts(parts);
        }
      } catch (e) {
        if (my === seq.current) {
          setValidation({ ok: false, errors: [{ message: (e as Error).message, kind: (e as ApiError).kind ?? 'Error' }], signals: {} });
          setCheckedParts(parts);
        }
      } finally {
        if (my === seq.current) setValidating(false);
      }
    }, 150);
    return () => clearTimeout(h);
    // validate what the diagram is, not where its blocks sit
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [api, doc.blocks, doc.wires, doc.parameters, doc.simulation, doc.params]);
  const fresh = !validating && [doc.blocks, doc.wires, doc.parameters, doc.simulation, doc.params].every((x, i) => x === checkedParts[i]);
  // the file as loaded or saved: does it run? (the first check of it, unchanged)
  useEffect(() => {
    if (fresh && validation && savedDoc === doc && savedRuns === null) setSavedRuns(validation.ok);
  }, [fresh, validation, savedDoc, doc, savedRuns]);

  // the toolbar's final time and step for this run: read, then checked by the library as the
  // run would take them (the document with them in place)
  useEffect(() => {
    const tf = readOverride(tFinal);
    const st = readOverride(dt);
    const local: ValidationError[] = [];
    if (tf.error) local.push({ message: tf.error, kind: 'NotApplied', field: 'toolbar.t_final' });
    if (st.error) local.push({ message: st.error, kind: 'NotApplied', field: 'toolbar.dt' });
    if (local.length || (tf.value === undefined && st.value === undefined)) {
      setOverrideErrors(local);
      return;
    }
    let live = true;
    const h = setTimeout(async () => {
      const sim = { ...(doc.simulation ?? {}) };
      if (tf.value !== undefined) sim.t_final = tf.value;
      if (st.value !== undefined) sim.dt = st.value;
      try {
        const v = await api.validate({ ...doc, simulation: sim }, file.path);
        if (!live) return;
        setOverrideErrors(
          v.errors
            .filter((e) => (e.field === 'simulation.t_final' && tf.value !== undefined) || (e.field === 'simulation.dt' && st.value !== undefined))
            .map((e) => ({ ...e, field: e.field!.replace('simulation.', 'toolbar.') })),
        );
      } catch {
        /* the document's own check reports it */
      }
    }, 200);
    return () => {
      live = false;
      clearTimeout(h);
    };
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [api, tFinal, dt, doc.blocks, doc.wires, doc.parameters, doc.simulation, doc.params]);

  const unreadErrors: ValidationError[] = useMemo(
    () =>
      Object.entries(unread).map(([field, message]) => {
        const m = /^blocks\.([^.]+)\./.exec(field);
        return { message, kind: 'NotApplied', field, block: m ? m[1] : null };
      }),
    [unread],
  );
  const errors = useMemo(() => [...unreadErrors, ...(validation?.errors ?? [])], [unreadErrors, validation]);
  const valid = (validation?.ok ?? false) && !unreadErrors.length;

  // ------------------------------------------------------------ canvas edits

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
    [selected],
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
    [selectedEdges],
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
    [doc, toast],
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
        setTab('props');
      } catch (e) {
        toast((e as Error).message, 'warn');
      }
    },
    [doc, level, palette, rf, toast, flow.nodes],
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
  }, [selected, selectedEdges, flow.edges, edit]);

  const copy = useCallback(() => {
    const items = [...selected].filter((n) => n !== IN_NODE && n !== OUT_NODE);
    if (!items.length) return false;
    clipboard.current = M.copyItems(doc, items);
    pasteCount.current = 0;
    toast(`copied ${Object.keys(clipboard.current.blocks).length} block(s)`);
    return true;
  }, [doc, selected, toast]);

  const pasteClip = useCallback(() => {
    if (!clipboard.current) return;
    pasteCount.current += 1;
    const off = 40 * pasteCount.current;
    const r = M.paste(doc, clipboard.current, [off, off], level);
    setHist((h) => M.commit(h, r.doc));
    setSelected(new Set(r.names));
  }, [doc, level]);

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
  }, [doc, selected, toast]);

  const ungroupSel = useCallback(() => {
    const gs = [...selected].filter((n) => n in (doc.editor?.groups ?? {}));
    if (!gs.length) return;
    edit((d) => gs.reduce((x, g) => M.ungroup(x, g), d));
    setSelected(new Set(gs.flatMap((g) => [...(doc.editor!.groups![g].blocks ?? []), ...(doc.editor!.groups![g].groups ?? [])])));
  }, [doc, selected, edit]);

  const autoLayout = useCallback(async () => {
    const pos = await layoutLevel(doc, palette, level);
    setHist((h) => M.commit(h, M.moveItems(h.present, pos)));
    view.moveSoon(() => fitRef.current(200));
  }, [doc, palette, level, view]);

  const openGroup = useCallback(
    (g: string) => {
      setPath((p) => [...p, g]);
      setSelected(new Set());
      setSelectedEdges(new Set());
      view.moveSoon(() => fitRef.current(150));
    },
    [view],
  );

  const leaveTo = useCallback(
    (depth: number) => {
      setPath((p) => p.slice(0, depth));
      setSelected(new Set());
      view.moveSoon(() => fitRef.current(150));
    },
    [view],
  );

  // ------------------------------------------------------------ files

  // (two serialisations of the whole document: once per edit, not once per render)
  const dirty = useMemo(() => savedDoc !== doc && JSON.stringify(savedDoc) !== JSON.stringify(doc), [savedDoc, doc]);

  const doSave = useCallback(
    async (p: string, opts: { force?: boolean; draft?: boolean } = {}) => {
      const draft = opts.draft ?? !valid;
      // saved under a new name, a diagram still called after its old file (or "untitled")
      // takes the new file's name: its runs' outputs go to avblocks-out/<name>
      let d = doc;
      const oldName = file.path ? stem(file.path) : (file.builtin ?? null);
      if (p !== file.path && (!doc.name || doc.name === 'untitled' || doc.name === oldName)) d = { ...doc, name: stem(p) };
      try {
        // a document opened from a built-in or another file keeps that file's comments and forms
        const r = await api.save(saveRequest(file, p, d, { force: opts.force, draft }));
        if (d !== doc) setHist((h) => M.commit(h, d));
        setFile({ path: r.path, builtin: null, revision: r.revision });
        setSavedDoc(d);
        setSavedRuns(!r.draft);
        setDialog(null);
        toast(r.draft ? `saved ${r.path} as a draft (it has problems: avblocks run will list them)` : `saved ${r.path}`, r.draft ? 'warn' : 'info');
      } catch (e) {
        if (e instanceof ApiError && e.status === 409) setDialog({ kind: 'conflict', path: p, draft, exists: e.kind === 'Exists' });
        else toast((e as Error).message, 'error');
      }
    },
    [api, doc, file, valid, toast],
  );

  const save = useCallback(() => {
    if (!file.path) setDialog({ kind: 'saveas', draft: !valid });
    // a file that runs is not replaced by a draft without asking
    else if (savedRuns === true && !valid && (fresh || unreadErrors.length)) setDialog({ kind: 'guard', path: file.path });
    else doSave(file.path);
  }, [file.path, doSave, valid, savedRuns, fresh, unreadErrors.length]);

  const openFiles = useCallback(async () => {
    setDialog({ kind: 'open' });
    try {
      setFiles(await api.files());
    } catch (e) {
      toast((e as Error).message, 'error');
    }
  }, [api, toast]);

  const newDoc = useCallback(async () => {
    try {
      await openDoc(await api.newDocument(), palette);
    } catch (e) {
      toast((e as Error).message, 'error');
    }
  }, [api, openDoc, palette, toast]);

  // ------------------------------------------------------------ problems

  const pickProblem = useCallback(
    (e: ValidationError) => {
      const f = e.field ?? '';
      if (f.startsWith('toolbar.')) {
        document.querySelector<HTMLInputElement>(`input[aria-label="${f === 'toolbar.dt' ? 'dt' : 't_final'}"]`)?.focus();
        return;
      }
      const fb = /^blocks\.([^.]+)\./.exec(f);
      const target = fb?.[1] ?? e.block ?? (e.wire ? M.refBlock(e.wire[1]) : e.cycle?.length ? M.refBlock(e.cycle[0]) : null);
      if (!target || !(target in doc.blocks)) {
        // about the diagram itself (its parameters, run settings, outcome): the diagram's panel
        setSelected(new Set());
        setSelectedEdges(new Set());
        setTab('props');
        return;
      }
      // go to the level that shows the block
      const chain: string[] = [];
      for (let g = M.parentOf(doc, target); g !== null; g = M.parentOf(doc, g)) chain.unshift(g);
      setPath(chain);
      setSelected(new Set([target]));
      setSelectedEdges(e.wire ? new Set([wireId(e.wire)]) : new Set());
      setTab('props');
      const pos = doc.editor?.layout?.[target];
      if (pos) view.moveSoon(() => rf.setCenter(pos[0] + 105, pos[1] + 40, { zoom: Math.max(rf.getZoom(), 0.9), duration: 200 }));
    },
    [doc, rf, view],
  );

  // ------------------------------------------------------------ run

  const runProblems = useCallback(
    (): ValidationError[] => [...overrideErrors, ...unreadErrors, ...(validation && !validation.ok && fresh ? validation.errors : [])],
    [overrideErrors, unreadErrors, validation, fresh],
  );

  const run = useCallback(() => {
    if (runs.running) return;
    const tf = readOverride(tFinal);
    const st = readOverride(dt);
    setTab('run');
    runs.closePlot();
    runs.start({ document: doc, backend, path: file.path, ...(tf.value !== undefined ? { t_final: tf.value } : {}), ...(st.value !== undefined ? { dt: st.value } : {}) }, runProblems());
  }, [runs, tFinal, dt, doc, backend, file.path, runProblems]);

  // a slider's change runs the diagram again (debounced), on the compiled engine
  const tuneTimer = useRef<number | null>(null);
  const tuneRun = useCallback(
    (d: Doc) => {
      if (tuneTimer.current) clearTimeout(tuneTimer.current);
      setTuneNote('running…');
      tuneTimer.current = window.setTimeout(async () => {
        if (runs.running) return tuneRun(d);
        const t0 = performance.now();
        const ok = await runs.start({ document: d, backend: 'jax', figures: false, path: file.path }, [...unreadErrors], {
          quiet: true,
          onEnd: (s) => setTuneNote(s.status === 'done' ? `ran again in ${((performance.now() - t0) / 1000).toFixed(2)} s: ${s.outcome ?? 'done'}` : `${s.status}: ${typeof s.error === 'string' ? s.error : (s.error?.message ?? '')}`),
        });
        if (!ok) setTuneNote('not run: see the Run tab');
      }, 250);
    },
    [runs, file.path, unreadErrors],
  );

  const live = useCallback(async () => {
    try {
      const { url } = await api.live(doc);
      window.open(url, '_blank');
      toast(`live view: ${url}`);
    } catch (e) {
      toast((e as Error).message, 'error');
    }
  }, [api, doc, toast]);

  const exportAs = useCallback(
    async (format: 'python' | 'svg' | 'png') => {
      try {
        const r = await api.export(doc, format);
        const base = (doc.name || 'diagram').replace(/[^\w.-]/g, '_');
        if (format === 'python') setDialog({ kind: 'export', text: r.text ?? '', filename: `${base}.py` });
        else if (r.data_url) download(`${base}.${format}`, r.data_url);
        else if (r.text) download(`${base}.${format}`, URL.createObjectURL(new Blob([r.text], { type: 'image/svg+xml' })));
      } catch (e) {
        toast((e as Error).message, 'error');
      }
    },
    [api, doc, toast],
  );

  const plotWire = useCallback(
    (w: Wire, add: boolean) => {
      setSelectedEdges(new Set([wireId(w)]));
      runs.plotWire(w, add);
    },
    [runs],
  );
  const onEdgeClick = useCallback((e: React.MouseEvent, edge: Edge) => plotWire((edge.data as { wire: Wire }).wire, e.shiftKey), [plotWire]);
  useEffect(() => {
    const on = (e: Event) => {
      const d = (e as CustomEvent).detail as { wire: Wire; add: boolean };
      plotWire(d.wire, d.add);
    };
    window.addEventListener(WIRE_CLICK, on);
    return () => window.removeEventListener(WIRE_CLICK, on);
  }, [plotWire]);

  // ------------------------------------------------------------ keyboard

  useKeyboard({
    dialogOpen: dialog !== null,
    save,
    saveAs: () => setDialog({ kind: 'saveas', draft: !valid }),
    search: () => searchRef.current?.focus(),
    undo: () => setHist(M.undo),
    redo: () => setHist(M.redo),
    copy,
    cut: () => {
      if (copy()) deleteSelection();
    },
    paste: pasteClip,
    duplicate: () => {
      if (copy()) pasteClip();
    },
    selectAll: () => setSelected(new Set(flow.nodes.filter((n) => n.type !== 'boundary').map((n) => n.id))),
    group,
    ungroup: ungroupSel,
    open: openFiles,
    run,
    remove: deleteSelection,
    help: () => setDialog({ kind: 'help' }),
    escape: () => {
      if (selected.size || selectedEdges.size) {
        setSelected(new Set());
        setSelectedEdges(new Set());
      } else if (path.length) leaveTo(path.length - 1);
      runs.closePlot();
    },
    enter: () => {
      if (selected.size !== 1) return false;
      const [s] = [...selected];
      if (!(s in (doc.editor?.groups ?? {}))) return false;
      openGroup(s);
      return true;
    },
    layout: autoLayout,
    fit: () => view.moveNow(() => fitShown(200)),
    fitSelection: () => view.moveNow(() => fitShown(200, selected)),
  });

  // ------------------------------------------------------------ render

  const selList = [...selected];
  const one = selList.length === 1 ? selList[0] : null;
  const title = file.path ?? (file.builtin ? `${file.builtin} (built-in)` : 'new diagram');

  let inspector: React.ReactNode;
  if (one && one in doc.blocks) {
    inspector = (
      <BlockPanel
        doc={doc}
        name={one}
        palette={palette}
        errors={errors}
        onRename={(to) => {
          try {
            const d = M.renameBlock(doc, one, to);
            setHist((h) => M.commit(h, d));
            setSelected(new Set([to]));
            return null;
          } catch (e) {
            return (e as Error).message;
          }
        }}
        onParam={(k, v) => edit((d) => M.setParam(d, one, k, v), `param:${one}.${k}`)}
      />
    );
  } else if (one && one in (doc.editor?.groups ?? {})) {
    inspector = <GroupPanel doc={doc} name={one} onLabel={(l) => edit((d) => M.renameGroupLabel(d, one, l), `label:${one}`)} onOpen={() => openGroup(one)} onUngroup={ungroupSel} />;
  } else if (!selList.length && selectedEdges.size === 1) {
    const e = flow.edges.find((x) => selectedEdges.has(x.id));
    inspector = e ? (
      <WirePanel
        wire={e.data.wire}
        shape={e.data.shape}
        errors={e.data.errors}
        logged={runs.status?.signals ?? null}
        inLog={Array.isArray(doc.simulation?.log) && (doc.simulation!.log as Json[]).includes(e.data.wire[0])}
        onLog={() =>
          edit((d) => {
            const cur = Array.isArray(d.simulation?.log) ? (d.simulation!.log as Json[]) : (runs.status?.signals ?? []);
            return M.setSimulation(d, 'log', [...cur.filter((x) => x !== e.data.wire[0]), e.data.wire[0]]);
          })
        }
        onDelete={deleteSelection}
      />
    ) : null;
  } else if (selList.length > 1) {
    inspector = <SelectionPanel count={selList.length} onGroup={group} onDelete={deleteSelection} />;
  } else {
    inspector = (
      <DiagramPanel
        doc={doc}
        errors={errors}
        onField={(k, v) => edit((d) => ({ ...d, [k]: v }), `doc:${k}`)}
        onParameter={(k, v) => edit((d) => M.setDiagramParameter(d, k, v as Json | undefined), `dparam:${k}`)}
        onSimulation={(k, v) => edit((d) => M.setSimulation(d, k, v), `sim:${k}`)}
      />
    );
  }

  const onOverride = (field: 'toolbar.t_final' | 'toolbar.dt') => overrideErrors.filter((e) => e.field === field).map((e) => e.message.replace(/^in parameter '\w+': /, ''));
  const shownErrors = [...overrideErrors, ...errors];
  const checkText = validating && !validation ? 'checking…' : valid && !overrideErrors.length ? '✓ builds' : `⚠ ${shownErrors.length} problem${shownErrors.length === 1 ? '' : 's'}`;

  return (
    <FieldStatusContext.Provider value={fieldStatus}>
      <HighlightContext.Provider value={highlight}>
        <div className="app">
          <Toolbar
            title={title}
            dirty={dirty}
            canUndo={hist.past.length > 0}
            canRedo={hist.future.length > 0}
            backend={backend}
            setBackend={setBackend}
            fields={{ tFinal, dt, setTFinal, setDt, errors: { t_final: onOverride('toolbar.t_final'), dt: onOverride('toolbar.dt') } }}
            sim={{ t_final: doc.simulation?.t_final as Json | undefined, dt: doc.simulation?.dt as Json | undefined }}
            running={runs.running}
            progress={runs.status?.progress ?? 0}
            check={{ text: checkText, cls: validating ? 'busy' : valid && !overrideErrors.length ? 'ok' : 'bad', fresh }}
            actions={{
              newDoc,
              open: openFiles,
              save,
              saveAs: () => setDialog({ kind: 'saveas', draft: !valid }),
              undo: () => setHist(M.undo),
              redo: () => setHist(M.redo),
              group,
              layout: autoLayout,
              run,
              stop: runs.stop,
              live,
              exportAs,
              help: () => setDialog({ kind: 'help' }),
              problems: () => setTab('problems'),
            }}
          />
          <div className="main">
            <PalettePanel palette={palette} onAdd={(t) => addAt(t)} searchRef={searchRef} />
            <div
              className={`canvas ${detail >= 1 ? 'far' : ''} ${detail >= 2 ? 'tiny' : ''}`}
              onDragOver={(e) => {
                e.preventDefault();
                e.dataTransfer.dropEffect = 'copy';
              }}
              onDrop={onDrop}
            >
              <div className="breadcrumb">
                <button className={path.length ? 'link' : 'here'} onClick={() => leaveTo(0)}>
                  {doc.name || 'diagram'}
                </button>
                {path.map((g, i) => (
                  <span key={g}>
                    {' › '}
                    <button className={i === path.length - 1 ? 'here' : 'link'} onClick={() => leaveTo(i + 1)}>
                      {doc.editor?.groups?.[g]?.label ?? g}
                    </button>
                  </span>
                ))}
              </div>
              <ReactFlow
                nodes={flow.nodes as Node[]}
                edges={flow.edges as unknown as Edge[]}
                nodeTypes={nodeTypes}
                edgeTypes={edgeTypes}
                onNodesChange={onNodesChange}
                onEdgesChange={onEdgesChange}
                onConnect={onConnect}
                isValidConnection={isValidConnection}
                onNodeDragStart={() => {
                  dragStart.current = true;
                }}
                onNodeDoubleClick={(_, n) => {
                  if (n.type === 'subsystem') openGroup(n.id);
                }}
                onEdgeClick={onEdgeClick}
                onEdgeMouseEnter={(_, e) => highlight.hoverWire(e.id)}
                onEdgeMouseLeave={() => highlight.hoverWire(null)}
                onPaneClick={() => runs.closePlot()}
                deleteKeyCode={null}
                selectionKeyCode="Shift"
                multiSelectionKeyCode={['Meta', 'Control', 'Shift']}
                selectionMode={SelectionMode.Partial}
                minZoom={0.05}
                maxZoom={3}
                defaultViewport={{ x: 0, y: 0, zoom: 1 }}
                onlyRenderVisibleElements
                proOptions={{ hideAttribution: true }}
                defaultEdgeOptions={{ type: 'wire' }}
                connectionRadius={24}
              >
                <Background gap={20} size={1} color="#d4d8de" />
                <MiniMap pannable zoomable nodeStrokeWidth={2} nodeColor={miniColor} />
                <Controls showInteractive={false} onFitView={() => view.moveNow(() => fitShown(200))} />
              </ReactFlow>
              {!Object.keys(doc.blocks).length ? (
                <div className="empty-hint">
                  <div className="big">Drag a block from the palette</div>
                  <div>
                    or press <kbd>/</kbd>, type its name and <kbd>Enter</kbd>. Wire an output (right) to an input (left). <kbd>?</kbd> lists the shortcuts.
                  </div>
                </div>
              ) : null}
              {runs.plot ? <PlotPanel signals={runs.plot} onRemove={runs.removePlotted} onClose={runs.closePlot} onCursor={runs.onCursor} agent={runs.agent} setAgent={runs.setAgent} /> : null}
              <div className="toasts">
                {toasts.map((t) => (
                  <div key={t.id} className={`toast ${t.kind}`} data-testid="toast">
                    {t.text}
                  </div>
                ))}
              </div>
            </div>
            <aside className="side">
              <div className="tabs">
                <button className={tab === 'props' ? 'on' : ''} onClick={() => setTab('props')}>
                  Properties
                </button>
                <button className={tab === 'problems' ? 'on' : ''} onClick={() => setTab('problems')} data-testid="tab-problems">
                  Problems {shownErrors.length ? <span className="badge">{shownErrors.length}</span> : null}
                </button>
                <button className={tab === 'run' ? 'on' : ''} onClick={() => setTab('run')} data-testid="tab-run">
                  Run
                </button>
                <button className={tab === 'tune' ? 'on' : ''} onClick={() => setTab('tune')} data-testid="tab-tune">
                  Tune
                </button>
              </div>
              <div className="side-body">
                {tab === 'props' ? inspector : null}
                {tab === 'problems' ? <ProblemsPanel errors={shownErrors} onPick={pickProblem} validating={validating} /> : null}
                {tab === 'run' ? <RunResults status={runs.status} fileUrl={(u) => transport.fileUrl(u)} hasRun={!!runs.runId} refused={runs.refused} onPick={pickProblem} /> : null}
                {tab === 'tune' ? (
                  <TunePanel
                    doc={doc}
                    palette={palette}
                    errors={errors}
                    auto={tuneAuto}
                    setAuto={setTuneAuto}
                    note={tuneNote}
                    onSet={(key, v) => {
                      const d = { ...doc, params: { ...((doc.params as Record<string, Json>) ?? {}), [key]: v } };
                      setHist((h) => M.commit(h, d, `tune:${key}`));
                      if (tuneAuto) tuneRun(d);
                    }}
                    onReset={() => {
                      const d = { ...doc };
                      delete d.params;
                      setHist((h) => M.commit(h, d));
                      if (tuneAuto) tuneRun(d);
                    }}
                  />
                ) : null}
              </div>
            </aside>
          </div>
          {dialog?.kind === 'open' ? <FilesDialog files={files} onOpen={loadFile} onClose={() => setDialog(null)} /> : null}
          {dialog?.kind === 'help' ? <HelpOverlay onClose={() => setDialog(null)} /> : null}
          {dialog?.kind === 'saveas' ? <SaveAs initial={file.path ?? `${(doc.name || 'diagram').replace(/[^\w.-]/g, '_')}.yaml`} draft={dialog.draft} onSave={(p) => doSave(p)} onClose={() => setDialog(null)} /> : null}
          {dialog?.kind === 'conflict' ? (
            <ConflictDialog
              path={dialog.path}
              exists={!!dialog.exists}
              onOverwrite={() => doSave(dialog.path, { force: true, draft: dialog.draft })}
              onReload={() => loadFile({ path: dialog.path })}
              onSaveAs={() => setDialog({ kind: 'saveas', draft: dialog.draft })}
              onClose={() => setDialog(null)}
            />
          ) : null}
          {dialog?.kind === 'guard' ? (
            <DraftGuard
              path={dialog.path}
              problems={shownErrors.length}
              onDraft={() => doSave(dialog.path, { draft: true })}
              onSaveAs={() => setDialog({ kind: 'saveas', draft: true })}
              onShow={() => {
                setDialog(null);
                setTab('problems');
              }}
              onClose={() => setDialog(null)}
            />
          ) : null}
          {dialog?.kind === 'export' ? (
            <ExportDialog
              text={dialog.text}
              filename={dialog.filename}
              onDownload={() => download(dialog.filename, URL.createObjectURL(new Blob([dialog.text], { type: 'text/x-python' })))}
              onCopy={() => navigator.clipboard?.writeText(dialog.text).then(() => toast('copied'))}
              onClose={() => setDialog(null)}
            />
          ) : null}
        </div>
      </HighlightContext.Provider>
    </FieldStatusContext.Provider>
  );
}

export function App({ transport }: { transport: Transport }) {
  return (
    <ReactFlowProvider>
      <Editor transport={transport} />
    </ReactFlowProvider>
  );
}
