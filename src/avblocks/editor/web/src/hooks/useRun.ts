// A run of the drawn diagram: start (or be refused with the problems that stop it), follow its
// progress, stop it, and plot its logged signals, several at once with a shared time cursor.

import { useCallback, useEffect, useRef, useState } from 'react';
import type { Doc, Json, RunStatus, SignalData, ValidationError, Wire } from '../types';
import type { Api } from '../transport';
import { ApiError } from '../transport';
import type { Highlight } from '../highlight';
import type { Plotted } from '../ui/PlotPanel';
import { valueText } from '../ui/PlotPanel';

export interface RunArgs {
  document: Doc;
  backend: string;
  t_final?: Json;
  dt?: Json;
  figures?: boolean;
  path?: string | null;
}

export function useRun({ api, toast, highlight }: { api: Api; toast: (t: string, k?: 'info' | 'warn' | 'error') => void; highlight: Highlight }) {
  const [runId, setRunId] = useState<string | null>(null);
  const [status, setStatus] = useState<RunStatus | null>(null);
  const [refused, setRefused] = useState<ValidationError[] | null>(null);
  const [plot, setPlot] = useState<Plotted[] | null>(null);
  const [agent, setAgent] = useState(0);
  const poll = useRef<number | null>(null);
  const plotRef = useRef<Plotted[] | null>(null);
  const stopping = useRef(false);
  plotRef.current = plot;
  const cursor = useRef<number | null>(null);
  const running = status?.status === 'running';

  useEffect(
    () => () => {
      if (poll.current) clearTimeout(poll.current);
    },
    [],
  );

  const fetchSignals = useCallback(
    async (id: string, names: string[]) => {
      const got: Plotted[] = [];
      for (const name of names) {
        try {
          got.push({ name, data: await api.signal(id, name) });
        } catch (e) {
          toast(`${name}: ${(e as Error).message}`, 'warn');
        }
      }
      return got;
    },
    [api, toast],
  );

  /** Start a run; `onEnd` is called with its last status. Problems known beforehand refuse it. */
  const start = useCallback(
    async (args: RunArgs, problems: ValidationError[], opts: { onEnd?: (s: RunStatus) => void; quiet?: boolean } = {}) => {
      if (running) return false;
      if (problems.length) {
        setRefused(problems);
        return false;
      }
      setRefused(null);
      stopping.current = false;
      if (!opts.quiet) setStatus({ status: 'running', progress: 0 });
      try {
        const { run: id } = await api.run(args);
        setRunId(id);
        setStatus({ status: 'running', progress: 0 });
        const follow = async () => {
          try {
            const s = await api.runStatus(id);
            setStatus(s);
            if (s.status === 'running') {
              // after Stop: ask often, so the page shows the end as soon as it comes
              poll.current = window.setTimeout(follow, stopping.current ? 40 : opts.quiet ? 120 : 250);
              return;
            }
            if (s.status === 'done' && !opts.quiet) toast(s.outcome ?? 'run finished');
            if (s.status === 'cancelled') toast(`stopped at t = ${+(s.t ?? 0).toPrecision(6)} s: what was computed until then can be plotted`);
            // the plotted signals follow the newest run
            const cur = plotRef.current;
            if (cur && cur.length && (s.status === 'done' || s.status === 'cancelled')) {
              const names = cur.map((p) => p.name).filter((n) => (s.signals ?? []).includes(n));
              fetchSignals(id, names).then((got) => setPlot((now) => (now ? got : now)));
            }
            opts.onEnd?.(s);
          } catch (e) {
            setStatus({ status: 'failed', progress: 0, error: (e as Error).message });
          }
        };
        follow();
        return true;
      } catch (e) {
        if (e instanceof ApiError && e.kind === 'InvalidDiagram' && e.errors.length) {
          setRefused(e.errors);
          setStatus(null);
        } else setStatus({ status: 'failed', progress: 0, error: (e as Error).message });
        return false;
      }
    },
    [api, running, toast, fetchSignals],
  );

  const stop = useCallback(() => {
    if (!runId) return;
    stopping.current = true;
    api.cancel(runId).catch((e) => toast((e as Error).message, 'error'));
  }, [api, runId, toast]);

  /** Plot a wire's signal (`add`: beside those plotted). */
  const plotWire = useCallback(
    async (w: Wire, add: boolean) => {
      if (!runId || !status) return false;
      if (status.status === 'running') {
        toast('the run is still going: click the wire again when it is done', 'info');
        return false;
      }
      const name = w[0];
      if (!(status.signals ?? []).includes(name)) {
        if (status.status === 'done' || status.status === 'cancelled') toast(`${name} was not logged in this run: select the wire and press "Log it"`, 'warn');
        return false;
      }
      const keep = add && plot ? plot.filter((p) => p.name !== name) : [];
      setPlot([...keep, { name, data: null }]);
      try {
        const data: SignalData = await api.signal(runId, name);
        setPlot((cur) => (cur ? cur.map((p) => (p.name === name ? { name, data } : p)) : cur));
      } catch (e) {
        setPlot((cur) => (cur ? cur.filter((p) => p.name !== name) : cur));
        toast(`${name}: ${(e as Error).message}`, 'warn');
      }
      return true;
    },
    [api, runId, status, plot, toast],
  );

  // the canvas shows each plotted signal's value at the cursor
  const showValues = useCallback(
    (t: number | null, signals: Plotted[] | null, a: number) => {
      const m = new Map<string, string>();
      if (t !== null) for (const p of signals ?? []) if (p.data && p.data.t.length) m.set(p.name, valueText(p.data, a, t));
      highlight.setValues(m);
    },
    [highlight],
  );
  const onCursor = useCallback(
    (t: number | null) => {
      cursor.current = t;
      showValues(t, plot, agent);
    },
    [showValues, plot, agent],
  );
  useEffect(() => showValues(cursor.current, plot, agent), [showValues, plot, agent]);

  const closePlot = useCallback(() => {
    setPlot(null);
    cursor.current = null;
    highlight.setValues(new Map());
  }, [highlight]);

  const reset = useCallback(() => {
    setStatus(null);
    setRunId(null);
    setRefused(null);
    closePlot();
  }, [closePlot]);

  return {
    runId,
    status,
    running,
    refused,
    setRefused,
    start,
    stop,
    plot,
    plotWire,
    removePlotted: (name: string) => setPlot((cur) => (cur ? cur.filter((p) => p.name !== name) : cur)),
    closePlot,
    onCursor,
    agent,
    setAgent,
    reset,
  };
}
