// The editor: owns the document (controlled React Flow), talks to the Python side through a Transport.

import { useCallback, useEffect, useMemo, useRef, useState } from 'react';
import { Background, Controls, MiniMap, ReactFlow, ReactFlowProvider, useReactFlow, useStore, SelectionMode } from '@xyflow/react';
import type { Connection, EdgeChange, NodeChange, Edge, Node } from '@xyflow/react';
import type { Doc, FileList, Json, Palette, RunStatus, SignalData, Validation, ValidationError, XY } from './types';
import * as M from './model';
import { handleRef, IN_NODE, OUT_NODE, stableFlow, toFlow, wireId } from './flow';
import type { FlowEdge, FlowNode } from './flow';
import { layoutAll, layoutLevel, needsLayout } from './layout';
import { Api, ApiError, saveRequest } from './transport';
import type { FileRef, Transport } from './transport';
import { nodeTypes, edgeTypes, WIRE_CLICK } from './nodes';
import {
  BlockPanel,
  DiagramPanel,
  DRAG_MIME,
  FilesDialog,
  GroupPanel,
  HelpOverlay,
  Modal,
  PalettePanel,
  ProblemsPanel,
  RunResults,
  SignalPlot,
  WirePanel,
} from './panels';

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
  | { kind: 'help' }
  | { kind: 'export'; text: string; filename: string };

function isTyping(e: KeyboardEvent): boolean {
  const t = e.target as HTMLElement | null;
  if (!t) return false;
  return t.tagName === 'INPUT' || t.tagName === 'TEXTAREA' || t.tagName === 'SELECT' || t.isContentEditable;
}

/** Fitting the view leaves room for what floats over the canvas: the breadcrumb (top left),
 * the zoom buttons (bottom left) and the minimap (bottom right, 200 x 150), so no block
 * is hidden under them. */
const FIT = { padding: { top: '52px', left: '64px', right: '40px', bottom: '180px' }, maxZoom: 1.2 } as const;

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

function Editor({ transport }: { transport: Transport }) {
  const api = useMemo(() => new Api(transport), [transport]);
  const rf = useReactFlow();
  // level of detail: zoomed far out, draw blocks without their text (faster, and unreadable anyway)
  // (one number per zoom band, so panning and zooming within a band render nothing here)
  const detail = useStore((s) => (s.transform[2] < 0.3 ? 2 : s.transform[2] < 0.45 ? 1 : 0));
  const [palette, setPalette] = useState<Palette | null>(null);
  const [hist, setHist] = useState<M.History>(() => M.history(M.emptyDocument()));
  const doc = hist.present;
  const [file, setFile] = useState<FileRef>({ path: null, builtin: null, revision: null });
  const [savedDoc, setSavedDoc] = useState<Doc | null>(doc);
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
  const [tab, setTab] = useState<'props' | 'problems' | 'run'>('props');
  const [backend, setBackend] = useState('numpy');
  const [tFinal, setTFinal] = useState('');
  const [dt, setDt] = useState('');
  const [runId, setRunId] = useState<string | null>(null);
  const [runStatus, setRunStatus] = useState<RunStatus | null>(null);
  const [plot, setPlot] = useState<{ name: string; data: SignalData | null } | null>(null);
  const clipboard = useRef<M.Fragment | null>(null);
  const pasteCount = useRef(0);
  const searchRef = useRef<HTMLInputElement>(null);
  const dragStart = useRef(false);
  // Moves of the view wait a frame or two for React Flow to measure what was just drawn.
  // Only the newest one may happen: a move scheduled earlier (a click on a problem centres
  // its block) must not land after, and undo, a fit the user asked for since.
  const pendingView = useRef<ReturnType<typeof setTimeout> | null>(null);
  const moveViewSoon = useCallback((move: () => void) => {
    if (pendingView.current !== null) clearTimeout(pendingView.current);
    pendingView.current = setTimeout(() => {
      pendingView.current = null;
      move();
    }, 30);
  }, []);
  const moveViewNow = useCallback((move: () => void) => {
    if (pendingView.current !== null) clearTimeout(pendingView.current);
    pendingView.current = null;
    move();
  }, []);
  const toastId = useRef(0);

  const toast = useCallback((text: string, kind: Toast['kind'] = 'info') => {
    const id = ++toastId.current;
    setToasts((t) => [...t.slice(-3), { id, text, kind }]);
    setTimeout(() => setToasts((t) => t.filter((x) => x.id !== id)), kind === 'error' ? 7000 : 4000);
  }, []);

  const edit = useCallback((f: (d: Doc) => Doc, key: string | null = null) => {
    setHist((h) => {
      try {
        return M.commit(h, f(h.present), key);
      } catch (e) {
        if (e instanceof M.ModelError) setTimeout(() => toast(e.message, 'warn'));
        else throw e;
        return h;
      }
    });
  }, [toast]);

  // ------------------------------------------------------------ loading

  const openDoc = useCallback(
    async (loaded: { document: Doc; path: string | null; builtin: string | null; revision: string | null }, pal: Palette | null) => {
      let d: Doc = { ...loaded.document, blocks: loaded.document.blocks ?? {}, wires: loaded.document.wires ?? [] };
      if (needsLayout(d)) d = await layoutAll(d, pal);
      setHist(M.history(d));
      setSavedDoc(d);
      setFile({ path: loaded.path, builtin: loaded.builtin, revision: loaded.revision });
      setPath([]);
      setSelected(new Set());
      setSelectedEdges(new Set());
      setRunStatus(null);
      setRunId(null);
      setPlot(null);
      if (Object.keys(d.blocks).length) moveViewSoon(() => rf.fitView({ ...FIT, duration: 0 }));
      else moveViewSoon(() => rf.setViewport({ x: 0, y: 0, zoom: 1 }));
    },
    [rf],
  );

  const started = useRef(false);
  useEffect(() => {
    if (started.current) return;
    started.current = true;
    const cancelled = false;
    (async () => {
      let pal: Palette | null = null;
      try {
        pal = await api.palette();
        if (!cancelled) setPalette(pal);
      } catch (e) {
        toast(`palette: ${(e as Error).message}`, 'error');
      }
      try {
        // the file `avblocks edit NAME|FILE` was started with, else an empty diagram
        const fl = await api.files();
        if (!cancelled) setFiles(fl);
        const initial = fl.initial;
        if (initial && !cancelled) {
          const loaded = await api.load(initial);
          if (!cancelled) await openDoc(loaded, pal);
        }
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
      const parts = [doc.blocks, doc.wires, doc.parameters, doc.simulation];
      try {
        const v = await api.validate(doc);
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
  }, [api, doc.blocks, doc.wires, doc.parameters, doc.simulation]);

  // ------------------------------------------------------------ the flow view

  // the nodes and edges that did not change keep their objects, so React Flow re-renders
  // only those that did (a block dragged, the one a check answered about), not all 500
  const lastFlow = useRef<{ nodes: FlowNode[]; edges: FlowEdge[] }>({ nodes: [], edges: [] });
  const flow = useMemo(() => {
    const next = stableFlow(lastFlow.current, toFlow(doc, palette, { level, validation, selected, selectedEdges }));
    lastFlow.current = next;
    return next;
  }, [doc, palette, level, validation, selected, selectedEdges]);

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

  // ------------------------------------------------------------ adding blocks

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

  // ------------------------------------------------------------ selection-wide edits

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
    moveViewSoon(() => rf.fitView({ ...FIT, duration: 200 }));
  }, [doc, palette, level, rf]);

  const openGroup = useCallback(
    (g: string) => {
      setPath((p) => [...p, g]);
      setSelected(new Set());
      setSelectedEdges(new Set());
      moveViewSoon(() => rf.fitView({ ...FIT, duration: 150 }));
    },
    [rf],
  );

  const leaveTo = useCallback(
    (depth: number) => {
      setPath((p) => p.slice(0, depth));
      setSelected(new Set());
      moveViewSoon(() => rf.fitView({ ...FIT, duration: 150 }));
    },
    [rf],
  );

  // ------------------------------------------------------------ files

  const valid = validation?.ok ?? false;
  // (two serialisations of the whole document: once per edit, not once per render)
  const dirty = useMemo(() => savedDoc !== doc && JSON.stringify(savedDoc) !== JSON.stringify(doc), [savedDoc, doc]);

  const doSave = useCallback(
    async (p: string, opts: { force?: boolean; draft?: boolean } = {}) => {
      const draft = opts.draft ?? !valid;
      try {
        // a document opened from a built-in or another file keeps that file's comments and forms
        const r = await api.save(saveRequest(file, p, doc, { force: opts.force, draft }));
        setFile({ path: r.path, builtin: null, revision: r.revision });
        setSavedDoc(doc);
        setDialog(null);
        toast(draft ? `saved ${r.path} as a draft (it has problems; avblocks run will report them)` : `saved ${r.path}`, draft ? 'warn' : 'info');
      } catch (e) {
        if (e instanceof ApiError && e.status === 409) setDialog({ kind: 'conflict', path: p, draft, exists: e.kind === 'Exists' });
        else toast((e as Error).message, 'error');
      }
    },
    [api, doc, file, valid, toast],
  );

  const save = useCallback(() => {
    if (file.path) doSave(file.path);
    else setDialog({ kind: 'saveas', draft: !valid });
  }, [file.path, doSave, valid]);

  const openFiles = useCallback(async () => {
    setDialog({ kind: 'open' });
    try {
      setFiles(await api.files());
    } catch (e) {
      toast((e as Error).message, 'error');
    }
  }, [api, toast]);

  const newDoc = useCallback(() => {
    openDoc({ document: M.emptyDocument(), path: null, builtin: null, revision: null }, palette);
  }, [openDoc, palette]);

  // ------------------------------------------------------------ run

  const pollRef = useRef<number | null>(null);
  const run = useCallback(async () => {
    if (runStatus?.status === 'running') return;
    const args: { document: Doc; backend: string; t_final?: number; dt?: number } = { document: doc, backend };
    if (tFinal.trim()) args.t_final = Number(tFinal);
    if (dt.trim()) args.dt = Number(dt);
    setTab('run');
    setPlot(null);
    setRunStatus({ status: 'running', progress: 0 });
    try {
      const { run: id } = await api.run(args);
      setRunId(id);
      const poll = async () => {
        try {
          const s = await api.runStatus(id);
          setRunStatus(s);
          if (s.status === 'running') pollRef.current = window.setTimeout(poll, 250);
          else if (s.status === 'done') toast(s.outcome ?? 'run finished');
        } catch (e) {
          setRunStatus({ status: 'failed', progress: 0, error: (e as Error).message });
        }
      };
      poll();
    } catch (e) {
      setRunStatus({ status: 'failed', progress: 0, error: (e as Error).message });
    }
  }, [api, doc, backend, tFinal, dt, runStatus, toast]);
  useEffect(() => () => {
    if (pollRef.current) clearTimeout(pollRef.current);
  }, []);

  const cancelRun = useCallback(() => {
    if (runId) api.cancel(runId).catch((e) => toast((e as Error).message, 'error'));
  }, [api, runId, toast]);

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
    async (w: [string, string]) => {
      setSelectedEdges(new Set([wireId(w)]));
      if (!runId || !runStatus) return;
      if (runStatus.status === 'running') return toast('the run is still going: click the wire again when it is done', 'info');
      if (runStatus.status !== 'done') return;
      const name = w[0];
      setPlot({ name, data: null });
      try {
        const data = await api.signal(runId, name);
        setPlot({ name, data });
      } catch (e) {
        setPlot(null);
        toast(`${name}: ${(e as Error).message}`, 'warn');
      }
    },
    [api, runId, runStatus, toast],
  );
  const onEdgeClick = useCallback((_: React.MouseEvent, edge: Edge) => plotWire((edge.data as { wire: [string, string] }).wire), [plotWire]);
  useEffect(() => {
    const on = (e: Event) => plotWire((e as CustomEvent).detail as [string, string]);
    window.addEventListener(WIRE_CLICK, on);
    return () => window.removeEventListener(WIRE_CLICK, on);
  }, [plotWire]);

  // ------------------------------------------------------------ problems

  const pickProblem = useCallback(
    (e: ValidationError) => {
      const target = e.block ?? (e.wire ? M.refBlock(e.wire[1]) : e.cycle?.length ? M.refBlock(e.cycle[0]) : null);
      if (!target || !(target in doc.blocks)) return;
      // go to the level that shows the block
      const chain: string[] = [];
      for (let g = M.parentOf(doc, target); g !== null; g = M.parentOf(doc, g)) chain.unshift(g);
      setPath(chain);
      setSelected(new Set([target]));
      setSelectedEdges(e.wire ? new Set([wireId(e.wire)]) : new Set());
      setTab('props');
      const pos = doc.editor?.layout?.[target];
      if (pos) moveViewSoon(() => rf.setCenter(pos[0] + 105, pos[1] + 40, { zoom: rf.getZoom(), duration: 200 }));
    },
    [doc, rf],
  );

  // ------------------------------------------------------------ keyboard

  // the key handler reads the latest state through a ref (set while rendering), so a
  // key pressed right after a click acts on that click's selection
  const keyState = {
    dialog, valid, save, copy, pasteClip, deleteSelection, group, ungroupSel, openFiles, run,
    selected, selectedEdges, path, leaveTo, doc, openGroup, autoLayout, rf, flow,
  };
  const keyRef = useRef(keyState);
  keyRef.current = keyState;
  useEffect(() => {
    const onKey = (e: KeyboardEvent) => {
      const {
        dialog, valid, save, copy, pasteClip, deleteSelection, group, ungroupSel, openFiles, run,
        selected, selectedEdges, path, leaveTo, doc, openGroup, autoLayout, rf, flow,
      } = keyRef.current;
      const mod = e.ctrlKey || e.metaKey;
      const k = e.key.toLowerCase();
      if (mod && k === 's') {
        e.preventDefault();
        if (e.shiftKey) setDialog({ kind: 'saveas', draft: !valid });
        else save();
        return;
      }
      if (dialog) return;
      if (mod && k === 'k') {
        e.preventDefault();
        searchRef.current?.focus();
        return;
      }
      if (isTyping(e)) return;
      if (mod && k === 'z' && !e.shiftKey) {
        e.preventDefault();
        setHist(M.undo);
      } else if (mod && ((k === 'z' && e.shiftKey) || k === 'y')) {
        e.preventDefault();
        setHist(M.redo);
      } else if (mod && k === 'c') {
        if (copy()) e.preventDefault();
      } else if (mod && k === 'x') {
        if (copy()) {
          e.preventDefault();
          deleteSelection();
        }
      } else if (mod && k === 'v') {
        e.preventDefault();
        pasteClip();
      } else if (mod && k === 'd') {
        e.preventDefault();
        if (copy()) pasteClip();
      } else if (mod && k === 'a') {
        e.preventDefault();
        setSelected(new Set(flow.nodes.filter((n) => n.type !== 'boundary').map((n) => n.id)));
      } else if (mod && k === 'g') {
        e.preventDefault();
        if (e.shiftKey) ungroupSel();
        else group();
      } else if (mod && k === 'o') {
        e.preventDefault();
        openFiles();
      } else if (mod && e.key === 'Enter') {
        e.preventDefault();
        run();
      } else if (e.key === 'Delete' || e.key === 'Backspace') {
        e.preventDefault();
        deleteSelection();
      } else if (e.key === '?') {
        setDialog({ kind: 'help' });
      } else if (e.key === '/') {
        e.preventDefault();
        searchRef.current?.focus();
      } else if (e.key === 'Escape') {
        if (selected.size || selectedEdges.size) {
          setSelected(new Set());
          setSelectedEdges(new Set());
        } else if (path.length) leaveTo(path.length - 1);
        setPlot(null);
      } else if (e.key === 'Enter' && selected.size === 1) {
        const [s] = [...selected];
        if (s in (doc.editor?.groups ?? {})) openGroup(s);
      } else if (!mod && k === 'l') {
        autoLayout();
      } else if (!mod && k === 'f') {
        moveViewNow(() => rf.fitView({ ...FIT, duration: 200 }));
      }
    };
    window.addEventListener('keydown', onKey);
    return () => window.removeEventListener('keydown', onKey);
  }, []);

  // ------------------------------------------------------------ render

  const errors = validation?.errors ?? [];
  const selList = [...selected];
  const one = selList.length === 1 ? selList[0] : null;
  const title = file.path ?? (file.builtin ? `${file.builtin} (built-in)` : 'new diagram');
  const running = runStatus?.status === 'running';
  const simT = doc.simulation?.t_final;
  const simDt = doc.simulation?.dt;

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
    inspector = (
      <GroupPanel
        doc={doc}
        name={one}
        onLabel={(l) => edit((d) => M.renameGroupLabel(d, one, l), `label:${one}`)}
        onOpen={() => openGroup(one)}
        onUngroup={ungroupSel}
      />
    );
  } else if (!selList.length && selectedEdges.size === 1) {
    const e = flow.edges.find((x) => selectedEdges.has(x.id));
    inspector = e ? (
      <WirePanel
        wire={e.data.wire}
        shape={e.data.shape}
        errors={e.data.errors}
        logged={runStatus?.signals ?? null}
        inLog={Array.isArray(doc.simulation?.log) && (doc.simulation!.log as Json[]).includes(e.data.wire[0])}
        onLog={() =>
          edit((d) => {
            const cur = Array.isArray(d.simulation?.log) ? (d.simulation!.log as Json[]) : (runStatus?.signals ?? []);
            return M.setSimulation(d, 'log', [...cur.filter((x) => x !== e.data.wire[0]), e.data.wire[0]]);
          })
        }
        onDelete={deleteSelection}
      />
    ) : null;
  } else if (selList.length > 1) {
    inspector = (
      <div className="inspector">
        <div className="insp-section">{selList.length} selected</div>
        <div className="row">
          <button onClick={group}>Group (Ctrl+G)</button>
          <button onClick={deleteSelection}>Delete</button>
        </div>
      </div>
    );
  } else {
    inspector = (
      <DiagramPanel
        doc={doc}
        onField={(k, v) => edit((d) => ({ ...d, [k]: v }), `doc:${k}`)}
        onParameter={(k, v) => edit((d) => M.setDiagramParameter(d, k, v as Json | undefined), `dparam:${k}`)}
        onSimulation={(k, v) => edit((d) => M.setSimulation(d, k, v), `sim:${k}`)}
      />
    );
  }

  return (
    <div className="app">
      <header className="toolbar">
        <div className="brand">
          avblocks <span className="muted">editor</span>
        </div>
        <div className="file-title" title={title} data-testid="file-title">
          {title}
          {dirty ? <span className="dirty" title="unsaved changes"> ●</span> : null}
        </div>
        <div className="tb-group">
          <button onClick={newDoc} title="New diagram">New</button>
          <button onClick={openFiles} title="Open (Ctrl+O)">Open</button>
          <button onClick={save} title="Save (Ctrl+S)" data-testid="save">Save</button>
          <button onClick={() => setDialog({ kind: 'saveas', draft: !valid })} title="Save as (Ctrl+Shift+S)">Save as</button>
        </div>
        <div className="tb-group">
          <button onClick={() => setHist(M.undo)} disabled={!hist.past.length} title="Undo (Ctrl+Z)" data-testid="undo">↶</button>
          <button onClick={() => setHist(M.redo)} disabled={!hist.future.length} title="Redo (Ctrl+Shift+Z)" data-testid="redo">↷</button>
          <button onClick={group} title="Group the selection (Ctrl+G)">Group</button>
          <button onClick={autoLayout} title="Automatic layout (L)">Layout</button>
        </div>
        <div className="tb-group run-group">
          <select value={backend} onChange={(e) => setBackend(e.target.value)} aria-label="Backend" title="Backend">
            <option value="numpy">NumPy</option>
            <option value="jax">JAX</option>
          </select>
          <label title="final time [s] (empty: the diagram's)">
            t<sub>f</sub>
            <input className="num" value={tFinal} placeholder={simT === undefined ? '' : M.valueToText(simT as Json)} onChange={(e) => setTFinal(e.target.value)} aria-label="t_final" />
          </label>
          <label title="step [s] (empty: the diagram's)">
            dt
            <input className="num" value={dt} placeholder={simDt === undefined ? '' : M.valueToText(simDt as Json)} onChange={(e) => setDt(e.target.value)} aria-label="dt" />
          </label>
          {running ? (
            <button className="danger" onClick={cancelRun}>Stop</button>
          ) : (
            <button className="primary" onClick={run} title="Run (Ctrl+Enter)" data-testid="run">▶ Run</button>
          )}
          <button onClick={live} title="Open the drawn diagram in the live view">Live</button>
        </div>
        <div className="tb-group">
          <select value="" onChange={(e) => e.target.value && exportAs(e.target.value as 'python' | 'svg' | 'png')} aria-label="Export" title="Export">
            <option value="">Export…</option>
            <option value="python">Python script</option>
            <option value="svg">SVG</option>
            <option value="png">PNG</option>
          </select>
          <button onClick={() => setDialog({ kind: 'help' })} title="Keyboard shortcuts (?)">?</button>
        </div>
        <div
          className={`check ${validating ? 'busy' : valid ? 'ok' : 'bad'}`}
          data-testid="check"
          data-fresh={String(!validating && [doc.blocks, doc.wires, doc.parameters, doc.simulation].every((x, i) => x === checkedParts[i]))}
          onClick={() => setTab('problems')}
        >
          {validating && !validation ? 'checking…' : valid ? '✓ builds' : `⚠ ${errors.length} problem${errors.length === 1 ? '' : 's'}`}
        </div>
        {running ? (
          <div className="progress" data-testid="progress">
            <div style={{ width: `${Math.round(100 * (runStatus?.progress ?? 0))}%` }} />
          </div>
        ) : null}
      </header>
      <div className="main">
        <PalettePanel palette={palette} onAdd={(t) => addAt(t)} searchRef={searchRef} />
        <div className={`canvas ${detail >= 1 ? 'far' : ''} ${detail >= 2 ? 'tiny' : ''}`} onDragOver={(e) => {
          e.preventDefault();
          e.dataTransfer.dropEffect = 'copy';
        }} onDrop={onDrop}>
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
            onPaneClick={() => setPlot(null)}
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
            <Controls showInteractive={false} />
          </ReactFlow>
          {!Object.keys(doc.blocks).length ? (
            <div className="empty-hint">
              <div className="big">Drag a block from the palette</div>
              <div>or press <kbd>/</kbd>, type its name and <kbd>Enter</kbd>. Wire an output (right) to an input (left). <kbd>?</kbd> lists the shortcuts.</div>
            </div>
          ) : null}
          {plot ? <SignalPlot name={plot.name} data={plot.data} onClose={() => setPlot(null)} /> : null}
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
            <button className={tab === 'props' ? 'on' : ''} onClick={() => setTab('props')}>Properties</button>
            <button className={tab === 'problems' ? 'on' : ''} onClick={() => setTab('problems')} data-testid="tab-problems">
              Problems {errors.length ? <span className="badge">{errors.length}</span> : null}
            </button>
            <button className={tab === 'run' ? 'on' : ''} onClick={() => setTab('run')} data-testid="tab-run">Run</button>
          </div>
          <div className="side-body">
            {tab === 'props' ? inspector : null}
            {tab === 'problems' ? <ProblemsPanel errors={errors} onPick={pickProblem} validating={validating} /> : null}
            {tab === 'run' ? <RunResults status={runStatus} fileUrl={(u) => transport.fileUrl(u)} hasRun={!!runId} /> : null}
          </div>
        </aside>
      </div>
      {dialog?.kind === 'open' ? <FilesDialog files={files} onOpen={loadFile} onClose={() => setDialog(null)} /> : null}
      {dialog?.kind === 'help' ? <HelpOverlay onClose={() => setDialog(null)} /> : null}
      {dialog?.kind === 'saveas' ? <SaveAs initial={file.path ?? `${(doc.name || 'diagram').replace(/[^\w.-]/g, '_')}.yaml`} draft={dialog.draft} onSave={(p) => doSave(p)} onClose={() => setDialog(null)} /> : null}
      {dialog?.kind === 'conflict' ? (
        <Modal title={dialog.exists ? 'The file exists' : 'The file changed on disk'} onClose={() => setDialog(null)}>
          <p>
            <span className="mono">{dialog.path}</span>{' '}
            {dialog.exists ? 'is another file that exists already.' : 'was changed by something else since it was opened.'}
          </p>
          <div className="row">
            <button className="danger" onClick={() => doSave(dialog.path, { force: true, draft: dialog.draft })} data-testid="overwrite">
              Overwrite it with this diagram
            </button>
            <button onClick={() => loadFile({ path: dialog.path })}>Reload it (drop my changes)</button>
            <button onClick={() => setDialog({ kind: 'saveas', draft: dialog.draft })}>Save as…</button>
          </div>
        </Modal>
      ) : null}
      {dialog?.kind === 'export' ? (
        <Modal title={`Export: ${dialog.filename}`} onClose={() => setDialog(null)}>
          <pre className="code">{dialog.text}</pre>
          <div className="row">
            <button className="primary" onClick={() => download(dialog.filename, URL.createObjectURL(new Blob([dialog.text], { type: 'text/x-python' })))}>
              Download
            </button>
            <button onClick={() => navigator.clipboard?.writeText(dialog.text).then(() => toast('copied'))}>Copy</button>
          </div>
        </Modal>
      ) : null}
    </div>
  );
}

function SaveAs({ initial, draft, onSave, onClose }: { initial: string; draft: boolean; onSave: (p: string) => void; onClose: () => void }) {
  const [p, setP] = useState(initial);
  const ok = /\.(ya?ml)$/.test(p) && !p.startsWith('/') && !p.split('/').includes('..');
  return (
    <Modal title="Save as" onClose={onClose}>
      <label className="row col">
        <span>file (relative to the editor's folder, .yaml)</span>
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
      {draft ? <p className="warn small">The diagram has problems: it is saved as a draft (as drawn; avblocks run will report them).</p> : null}
      <div className="row">
        <button className="primary" disabled={!ok} onClick={() => onSave(p)} data-testid="saveas-ok">
          Save
        </button>
        <button onClick={onClose}>Cancel</button>
      </div>
    </Modal>
  );
}

export function App({ transport }: { transport: Transport }) {
  return (
    <ReactFlowProvider>
      <Editor transport={transport} />
    </ReactFlowProvider>
  );
}
