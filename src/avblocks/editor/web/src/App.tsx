// The editor: owns the document (controlled React Flow) and composes the parts, each in a
// module of its own: the toolbar, palette, canvas, properties, problems, run and tune tabs,
// plot panel and dialogs (ui/); checks, files, canvas edits, runs, keys and view moves
// (hooks/); the document model (model.ts), the flow view (flow.ts), wire routing (router.ts,
// routes.ts), search (search.ts), the canvas's highlights (highlight.ts).

import { useCallback, useEffect, useMemo, useRef, useState } from 'react';
import { ReactFlowProvider, useReactFlow, useStore } from '@xyflow/react';
import type { Edge } from '@xyflow/react';
import type { Doc, Json, Loaded, Palette, ValidationError, Wire } from './types';
import * as M from './model';
import { routed, stableFlow, toFlow, wireId } from './flow';
import type { FlowEdge, FlowNode } from './flow';
import { Api } from './transport';
import type { Transport } from './transport';
import { HighlightContext, WIRE_CLICK } from './nodes';
import { Highlight } from './highlight';
import { Wiring } from './routes';
import { PalettePanel } from './ui/Palette';
import { FieldStatusContext } from './ui/Fields';
import { BlockPanel, DiagramPanel, GroupPanel, SelectionPanel, WirePanel } from './ui/Inspector';
import { ProblemsPanel } from './ui/Problems';
import { RunResults } from './ui/RunPanel';
import { PlotPanel } from './ui/PlotPanel';
import { TunePanel } from './ui/Tune';
import { Toolbar } from './ui/Toolbar';
import { Canvas } from './ui/Canvas';
import type { Toast } from './ui/Canvas';
import { Side } from './ui/Side';
import type { Tab } from './ui/Side';
import { ConflictDialog, DraftGuard, ExportDialog, FilesDialog, HelpOverlay, SaveAs } from './ui/Dialogs';
import { useKeyboard } from './hooks/useKeyboard';
import { useViewMoves } from './hooks/useViewMoves';
import { useRun } from './hooks/useRun';
import { readOverride, useChecks } from './hooks/useChecks';
import { useEdits } from './hooks/useEdits';
import { useFiles } from './hooks/useFiles';
import type { FileDialog } from './hooks/useFiles';

type Dialog = FileDialog | { kind: 'help' } | { kind: 'export'; text: string; filename: string };

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
  const view = useViewMoves(rf);
  const highlight = useMemo(() => new Highlight(), []);
  // level of detail: zoomed far out, draw blocks without their text (faster, and unreadable anyway)
  // (one number per zoom band, so panning and zooming within a band render nothing here)
  const detail = useStore((s) => (s.transform[2] < 0.3 ? 2 : s.transform[2] < 0.45 ? 1 : 0));
  const [palette, setPalette] = useState<Palette | null>(null);
  const [hist, setHist] = useState<M.History>(() => M.history(M.emptyDocument()));
  const doc = hist.present;
  // the document the page starts with, until the server's new one (or the file) comes
  const first = useRef(doc);
  const current = useRef(doc);
  current.current = doc;
  const [path, setPath] = useState<string[]>([]);
  const level = path.length ? path[path.length - 1] : null;
  const [selected, setSelected] = useState<Set<string>>(new Set());
  const [selectedEdges, setSelectedEdges] = useState<Set<string>>(new Set());
  const [toasts, setToasts] = useState<Toast[]>([]);
  const [dialog, setDialog] = useState<Dialog>(null);
  const [tab, setTab] = useState<Tab>('props');
  const [backend, setBackend] = useState('numpy');
  const [tFinal, setTFinal] = useState('');
  const [dt, setDt] = useState('');
  const [tuneAuto, setTuneAuto] = useState(true);
  const [tuneNote, setTuneNote] = useState<string | null>(null);
  const searchRef = useRef<HTMLInputElement>(null);
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
  const [filePath, setFilePath] = useState<string | null>(null);
  const checks = useChecks({ api, doc, path: filePath, tFinal, dt });
  const { validation, validating, fresh, overrideErrors, errors, valid } = checks;
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

  // ------------------------------------------------------------ files

  const onOpened = useCallback(
    (d: Doc) => {
      wirings.current.clear();
      setPath([]);
      setSelected(new Set());
      setSelectedEdges(new Set());
      runs.reset();
      if (Object.keys(d.blocks).length) view.moveSoon(() => fitRef.current(0));
      else view.moveSoon(() => rf.setViewport({ x: 0, y: 0, zoom: 1 }));
    },
    [rf, view, runs.reset],
  );
  const files = useFiles({
    api,
    doc,
    setHist,
    toast,
    check: { valid, fresh, ok: fresh && validation ? validation.ok : null, pendingText: checks.unreadErrors.length > 0 },
    setDialog,
    onOpened,
  });
  useEffect(() => setFilePath(files.file.path), [files.file.path]);

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
        files.setFiles(fl);
        const loaded: Loaded = fl.initial ? await api.load(fl.initial) : await api.newDocument();
        // (a new diagram the user has started drawing meanwhile is kept: it is one already)
        if (fl.initial || current.current === first.current) await files.openDoc(loaded, pal);
      } catch (e) {
        toast((e as Error).message, 'error');
      }
    })();
  }, [api, files, toast]);

  // ------------------------------------------------------------ canvas edits

  const edits = useEdits({
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
    moveSoon: view.moveSoon,
    fitRef,
    onAdded: () => setTab('props'),
  });

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

  const run = useCallback(() => {
    if (runs.running) return;
    const tf = readOverride(tFinal);
    const st = readOverride(dt);
    setTab('run');
    runs.closePlot();
    runs.start(
      { document: doc, backend, path: files.file.path, ...(tf.value !== undefined ? { t_final: tf.value } : {}), ...(st.value !== undefined ? { dt: st.value } : {}) },
      checks.runProblems(),
    );
  }, [runs, tFinal, dt, doc, backend, files.file.path, checks]);

  // a slider's change runs the diagram again (debounced), on the compiled engine
  const tuneTimer = useRef<number | null>(null);
  const tuneRun = useCallback(
    (d: Doc) => {
      if (tuneTimer.current) clearTimeout(tuneTimer.current);
      setTuneNote('running…');
      tuneTimer.current = window.setTimeout(async () => {
        if (runs.running) return tuneRun(d);
        const t0 = performance.now();
        const ok = await runs.start({ document: d, backend: 'jax', figures: false, path: files.file.path }, [...checks.unreadErrors], {
          quiet: true,
          onEnd: (s) => setTuneNote(s.status === 'done' ? `ran again in ${((performance.now() - t0) / 1000).toFixed(2)} s: ${s.outcome ?? 'done'}` : `${s.status}: ${typeof s.error === 'string' ? s.error : (s.error?.message ?? '')}`),
        });
        if (!ok) setTuneNote('not run: see the Run tab');
      }, 250);
    },
    [runs, files.file.path, checks.unreadErrors],
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

  const saveAs = () => setDialog({ kind: 'saveas', draft: !valid });
  useKeyboard({
    dialogOpen: dialog !== null,
    save: files.save,
    saveAs,
    search: () => searchRef.current?.focus(),
    undo: () => setHist(M.undo),
    redo: () => setHist(M.redo),
    copy: edits.copy,
    cut: edits.cut,
    paste: edits.paste,
    duplicate: edits.duplicate,
    selectAll: edits.selectAll,
    group: edits.group,
    ungroup: edits.ungroup,
    open: files.openFiles,
    run,
    remove: edits.deleteSelection,
    help: () => setDialog({ kind: 'help' }),
    escape: () => {
      edits.escape();
      runs.closePlot();
    },
    enter: edits.enter,
    layout: edits.autoLayout,
    fit: () => view.moveNow(() => fitShown(200)),
    fitSelection: () => view.moveNow(() => fitShown(200, selected)),
  });

  // ------------------------------------------------------------ render

  const selList = [...selected];
  const one = selList.length === 1 ? selList[0] : null;
  const file = files.file;
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
    inspector = <GroupPanel doc={doc} name={one} onLabel={(l) => edit((d) => M.renameGroupLabel(d, one, l), `label:${one}`)} onOpen={() => edits.openGroup(one)} onUngroup={edits.ungroup} />;
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
        onDelete={edits.deleteSelection}
      />
    ) : null;
  } else if (selList.length > 1) {
    inspector = <SelectionPanel count={selList.length} onGroup={edits.group} onDelete={edits.deleteSelection} />;
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
  const builds = valid && !overrideErrors.length;
  const checkText = validating && !validation ? 'checking…' : builds ? '✓ builds' : `⚠ ${shownErrors.length} problem${shownErrors.length === 1 ? '' : 's'}`;

  return (
    <FieldStatusContext.Provider value={checks.fieldStatus}>
      <HighlightContext.Provider value={highlight}>
        <div className="app">
          <Toolbar
            title={title}
            dirty={files.dirty}
            canUndo={hist.past.length > 0}
            canRedo={hist.future.length > 0}
            backend={backend}
            setBackend={setBackend}
            fields={{ tFinal, dt, setTFinal, setDt, errors: { t_final: onOverride('toolbar.t_final'), dt: onOverride('toolbar.dt') } }}
            sim={{ t_final: doc.simulation?.t_final as Json | undefined, dt: doc.simulation?.dt as Json | undefined }}
            running={runs.running}
            progress={runs.status?.progress ?? 0}
            check={{ text: checkText, cls: validating ? 'busy' : builds ? 'ok' : 'bad', fresh }}
            actions={{
              newDoc: () => files.newDoc(palette),
              open: files.openFiles,
              save: files.save,
              saveAs,
              undo: () => setHist(M.undo),
              redo: () => setHist(M.redo),
              group: edits.group,
              layout: edits.autoLayout,
              run,
              stop: runs.stop,
              live,
              exportAs,
              help: () => setDialog({ kind: 'help' }),
              problems: () => setTab('problems'),
            }}
          />
          <div className="main">
            <PalettePanel palette={palette} onAdd={(t) => edits.addAt(t)} searchRef={searchRef} />
            <Canvas
              doc={doc}
              flow={flow}
              path={path}
              detail={detail}
              highlight={highlight}
              toasts={toasts}
              edits={edits}
              onEdgeClick={onEdgeClick}
              onPaneClick={() => runs.closePlot()}
              onFit={() => view.moveNow(() => fitShown(200))}
              plot={runs.plot ? <PlotPanel signals={runs.plot} onRemove={runs.removePlotted} onClose={runs.closePlot} onCursor={runs.onCursor} agent={runs.agent} setAgent={runs.setAgent} /> : null}
            />
            <Side tab={tab} setTab={setTab} problems={shownErrors.length}>
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
            </Side>
          </div>
          {dialog?.kind === 'open' ? <FilesDialog files={files.files} onOpen={(a) => files.loadFile(a, palette)} onClose={() => setDialog(null)} /> : null}
          {dialog?.kind === 'help' ? <HelpOverlay onClose={() => setDialog(null)} /> : null}
          {dialog?.kind === 'saveas' ? <SaveAs initial={file.path ?? `${(doc.name || 'diagram').replace(/[^\w.-]/g, '_')}.yaml`} draft={dialog.draft} onSave={(p) => files.doSave(p)} onClose={() => setDialog(null)} /> : null}
          {dialog?.kind === 'conflict' ? (
            <ConflictDialog
              path={dialog.path}
              exists={!!dialog.exists}
              onOverwrite={() => files.doSave(dialog.path, { force: true, draft: dialog.draft })}
              onReload={() => files.loadFile({ path: dialog.path }, palette)}
              onSaveAs={() => setDialog({ kind: 'saveas', draft: dialog.draft })}
              onClose={() => setDialog(null)}
            />
          ) : null}
          {dialog?.kind === 'guard' ? (
            <DraftGuard
              path={dialog.path}
              problems={shownErrors.length}
              onDraft={() => files.doSave(dialog.path, { draft: true })}
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
