// The editor's keys (the help overlay lists them). The handler reads the latest actions
// through a ref set while rendering, so a key pressed right after a click acts on that click.

import { useEffect, useRef } from 'react';

export interface KeyActions {
  dialogOpen: boolean;
  save: () => void;
  saveAs: () => void;
  search: () => void;
  undo: () => void;
  redo: () => void;
  copy: () => boolean;
  cut: () => void;
  paste: () => void;
  duplicate: () => void;
  selectAll: () => void;
  group: () => void;
  ungroup: () => void;
  open: () => void;
  run: () => void;
  remove: () => void;
  help: () => void;
  escape: () => void;
  enter: () => boolean;
  layout: () => void;
  fit: () => void;
  fitSelection: () => void;
}

function isTyping(e: KeyboardEvent): boolean {
  const t = e.target as HTMLElement | null;
  if (!t) return false;
  return t.tagName === 'INPUT' || t.tagName === 'TEXTAREA' || t.tagName === 'SELECT' || t.isContentEditable;
}

export function useKeyboard(actions: KeyActions) {
  const ref = useRef(actions);
  ref.current = actions;
  useEffect(() => {
    const onKey = (e: KeyboardEvent) => {
      const a = ref.current;
      const mod = e.ctrlKey || e.metaKey;
      const k = e.key.toLowerCase();
      if (mod && k === 's') {
        e.preventDefault();
        if (e.shiftKey) a.saveAs();
        else a.save();
        return;
      }
      if (a.dialogOpen) return;
      if (mod && k === 'k') {
        e.preventDefault();
        a.search();
        return;
      }
      if (isTyping(e)) return;
      if (mod && k === 'z' && !e.shiftKey) {
        e.preventDefault();
        a.undo();
      } else if (mod && ((k === 'z' && e.shiftKey) || k === 'y')) {
        e.preventDefault();
        a.redo();
      } else if (mod && k === 'c') {
        if (a.copy()) e.preventDefault();
      } else if (mod && k === 'x') {
        e.preventDefault();
        a.cut();
      } else if (mod && k === 'v') {
        e.preventDefault();
        a.paste();
      } else if (mod && k === 'd') {
        e.preventDefault();
        a.duplicate();
      } else if (mod && k === 'a') {
        e.preventDefault();
        a.selectAll();
      } else if (mod && k === 'g') {
        e.preventDefault();
        if (e.shiftKey) a.ungroup();
        else a.group();
      } else if (mod && k === 'o') {
        e.preventDefault();
        a.open();
      } else if (mod && e.key === 'Enter') {
        e.preventDefault();
        a.run();
      } else if (e.key === 'Delete' || e.key === 'Backspace') {
        e.preventDefault();
        a.remove();
      } else if (e.key === '?') {
        a.help();
      } else if (e.key === '/') {
        e.preventDefault();
        a.search();
      } else if (e.key === 'Escape') {
        a.escape();
      } else if (e.key === 'Enter') {
        if (a.enter()) e.preventDefault();
      } else if (!mod && k === 'l') {
        a.layout();
      } else if (!mod && k === 'f') {
        if (e.shiftKey) a.fitSelection();
        else a.fit();
      }
    };
    window.addEventListener('keydown', onKey);
    return () => window.removeEventListener('keydown', onKey);
  }, []);
}
