// The library's check of the document as it is drawn (debounced), of the toolbar's final
// time and step for the next run, and the fields whose text the page could not read: every
// problem the page shows, and whether the diagram runs.

import { useEffect, useMemo, useRef, useState } from 'react';
import type { Doc, Json, Validation, ValidationError } from '../types';
import * as M from '../model';
import type { Api } from '../transport';
import { ApiError } from '../transport';

/** A toolbar field's text as the value a run gets (empty: none; unreadable: a problem). */
export function readOverride(text: string): { value?: Json; error?: string } {
  if (!text.trim()) return {};
  try {
    return { value: M.parseValue(text) };
  } catch (e) {
    return { error: `not applied: ${(e as Error).message}` };
  }
}

/** The parts of a document its check is about (not where its blocks sit). */
const partsOf = (doc: Doc) => [doc.blocks, doc.wires, doc.parameters, doc.simulation, doc.params];

export function useChecks({ api, doc, path, tFinal, dt }: { api: Api; doc: Doc; path: string | null; tFinal: string; dt: string }) {
  const [validation, setValidation] = useState<Validation | null>(null);
  const [validating, setValidating] = useState(false);
  // what the last answer was about: the check is fresh when it is the document as it is now
  const [checkedParts, setCheckedParts] = useState<unknown[]>([]);
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

  const seq = useRef(0);
  useEffect(() => {
    const my = ++seq.current;
    setValidating(true);
    const h = setTimeout(async () => {
      const parts = partsOf(doc);
      try {
        const v = await api.validate(doc, path);
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
  }, [api, ...partsOf(doc)]);
  const fresh = !validating && partsOf(doc).every((x, i) => x === checkedParts[i]);

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
        const v = await api.validate({ ...doc, simulation: sim }, path);
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
  }, [api, tFinal, dt, ...partsOf(doc)]);

  const unreadErrors: ValidationError[] = useMemo(
    () =>
      Object.entries(unread).map(([field, message]) => {
        const m = /^blocks\.([^.]+)\./.exec(field);
        return { message, kind: 'NotApplied', field, block: m ? m[1] : null };
      }),
    [unread],
  );
  /** Problems of the document (text not read first). */
  const errors = useMemo(() => [...unreadErrors, ...(validation?.errors ?? [])], [unreadErrors, validation]);
  const valid = (validation?.ok ?? false) && !unreadErrors.length;
  /** What stops a run now: the toolbar's fields, text not read, the check's errors. */
  const runProblems = (): ValidationError[] => [...overrideErrors, ...unreadErrors, ...(validation && !validation.ok && fresh ? validation.errors : [])];
  return { validation, validating, fresh, overrideErrors, fieldStatus, unreadErrors, errors, valid, runProblems };
}
