// Files: the document's origin (a file under the editor's folder, a built-in, or new), whether
// the file as last loaded or saved runs, saving (a draft never silently replaces a file that
// runs; "save as" names the diagram after its file), opening, a new diagram (GET new).

import { useCallback, useEffect, useMemo, useState } from 'react';
import type { Dispatch, SetStateAction } from 'react';
import type { Doc, FileList, Loaded, Palette } from '../types';
import * as M from '../model';
import type { Api, FileRef } from '../transport';
import { ApiError, saveRequest } from '../transport';
import { layoutAll, needsLayout } from '../layout';

export type FileDialog = null | { kind: 'open' } | { kind: 'saveas'; draft: boolean } | { kind: 'conflict'; path: string; draft: boolean; exists?: boolean } | { kind: 'guard'; path: string };

/** The stem of a file path: "dir/my_team.yaml" -> "my_team". */
export function stem(p: string): string {
  return (p.split('/').pop() ?? p).replace(/\.(ya?ml)$/, '');
}

export function useFiles({
  api,
  doc,
  setHist,
  toast,
  check,
  setDialog,
  onOpened,
}: {
  api: Api;
  doc: Doc;
  setHist: Dispatch<SetStateAction<M.History>>;
  toast: (t: string, k?: 'info' | 'warn' | 'error') => void;
  check: { valid: boolean; fresh: boolean; ok: boolean | null; pendingText: boolean };
  setDialog: (d: FileDialog) => void;
  onOpened: (d: Doc) => void;
}) {
  const [file, setFile] = useState<FileRef>({ path: null, builtin: null, revision: null });
  const [savedDoc, setSavedDoc] = useState<Doc | null>(doc);
  // whether the file as last loaded or saved runs (its first check, or the save's answer)
  const [savedRuns, setSavedRuns] = useState<boolean | null>(null);
  const [files, setFiles] = useState<FileList | null>(null);
  // (two serialisations of the whole document: once per edit, not once per render)
  const dirty = useMemo(() => savedDoc !== doc && JSON.stringify(savedDoc) !== JSON.stringify(doc), [savedDoc, doc]);
  useEffect(() => {
    if (check.fresh && check.ok !== null && savedDoc === doc && savedRuns === null) setSavedRuns(check.ok);
  }, [check.fresh, check.ok, savedDoc, doc, savedRuns]);

  const openDoc = useCallback(
    async (loaded: Loaded, pal: Palette | null) => {
      let d: Doc = { ...loaded.document, blocks: loaded.document.blocks ?? {}, wires: loaded.document.wires ?? [] };
      if (needsLayout(d)) d = await layoutAll(d, pal);
      setHist(M.history(d));
      setSavedDoc(d);
      setSavedRuns(null);
      setFile({ path: loaded.path, builtin: loaded.builtin, revision: loaded.revision });
      onOpened(d);
    },
    [setHist, onOpened],
  );

  const loadFile = useCallback(
    async (a: { path?: string; builtin?: string }, pal: Palette | null) => {
      setDialog(null);
      try {
        const loaded = await api.load(a);
        await openDoc(loaded, pal);
        toast(`opened ${loaded.path ?? loaded.builtin}`);
      } catch (e) {
        toast((e as Error).message, 'error');
      }
    },
    [api, openDoc, toast, setDialog],
  );

  const doSave = useCallback(
    async (p: string, opts: { force?: boolean; draft?: boolean } = {}) => {
      const draft = opts.draft ?? !check.valid;
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
    [api, doc, file, check.valid, toast, setHist, setDialog],
  );

  const save = useCallback(() => {
    if (!file.path) setDialog({ kind: 'saveas', draft: !check.valid });
    // a file that runs is not replaced by a draft without asking
    else if (savedRuns === true && !check.valid && (check.fresh || check.pendingText)) setDialog({ kind: 'guard', path: file.path });
    else doSave(file.path);
  }, [file.path, doSave, check.valid, check.fresh, check.pendingText, savedRuns, setDialog]);

  const openFiles = useCallback(async () => {
    setDialog({ kind: 'open' });
    try {
      setFiles(await api.files());
    } catch (e) {
      toast((e as Error).message, 'error');
    }
  }, [api, toast, setDialog]);

  const newDoc = useCallback(
    async (pal: Palette | null) => {
      try {
        await openDoc(await api.newDocument(), pal);
      } catch (e) {
        toast((e as Error).message, 'error');
      }
    },
    [api, openDoc, toast],
  );

  return { file, dirty, files, setFiles, openDoc, loadFile, doSave, save, openFiles, newDoc };
}
