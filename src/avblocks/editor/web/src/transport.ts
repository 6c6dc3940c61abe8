// One interface to the Python side, two ways to reach it (HTTP page, anywidget).

import type { Doc, FileList, Json, Loaded, Palette, RunStatus, SignalData, Validation, ValidationError } from './types';

export class ApiError extends Error {
  status: number;
  kind: string;
  /** For `InvalidDiagram`: the check's error records (API.md). */
  errors: ValidationError[];
  constructor(message: string, status = 400, kind = 'Error', errors: ValidationError[] = []) {
    super(message);
    this.status = status;
    this.kind = kind;
    this.errors = errors;
  }
}

/** JSON text of a request: a number JSON cannot write (NaN, an infinity, what a field
 * reads from `.nan` or `1e999`) is written as Python's json module reads it (NaN,
 * Infinity, -Infinity), so the library judges the value typed instead of a null. */
export function toJson(v: unknown): string {
  // a marker no text typed holds (a random tag per request)
  const tag = `\u0000${Math.random().toString(36).slice(2)}:`;
  const s = JSON.stringify(v, (_k, x) => (typeof x === 'number' && !Number.isFinite(x) ? `${tag}${Number.isNaN(x) ? 'NaN' : x > 0 ? 'Infinity' : '-Infinity'}` : x));
  const quoted = JSON.stringify(tag).slice(1, -1).replace(/[\\^$.*+?()[\]{}|]/g, '\\$&');
  return s.replace(new RegExp(`"${quoted}(NaN|Infinity|-Infinity)"`, 'g'), '$1');
}

/** A JSON answer, where a number JSON has no word for may come as Python's json module
 * writes it (NaN, Infinity, -Infinity: a draft file holding `.nan`). */
export function fromJson(text: string): unknown {
  try {
    return JSON.parse(text);
  } catch (e) {
    if (!/NaN|Infinity/.test(text)) throw e;
  }
  const marks: number[] = [];
  // outside strings only: a string is skipped whole, a bare token becomes a marker
  const t = text.replace(/("(?:[^"\\]|\\.)*")|(-?Infinity|NaN)/g, (m, str, tok) => {
    if (str) return str;
    marks.push(tok === 'NaN' ? NaN : tok.startsWith('-') ? -Infinity : Infinity);
    return `{"\\u0000": ${marks.length - 1}}`;
  });
  const unmark = (v: unknown): unknown => {
    if (Array.isArray(v)) return v.map(unmark);
    if (v && typeof v === 'object') {
      const o = v as Record<string, unknown>;
      const keys = Object.keys(o);
      if (keys.length === 1 && keys[0] === '\u0000') return marks[o['\u0000'] as number];
      return Object.fromEntries(keys.map((k) => [k, unmark(o[k])]));
    }
    return v;
  };
  return unmark(JSON.parse(t));
}

export interface Transport {
  call<T>(op: string, args?: Record<string, unknown>, method?: 'GET' | 'POST'): Promise<T>;
  /** A URL (or data URL) the page can show for a figure the server returned. */
  fileUrl(url: string): string;
}

export class HttpTransport implements Transport {
  base: string;
  constructor(base?: string) {
    if (base === undefined) {
      // everything up to and including "/<token>/"
      const m = location.pathname.match(/^\/[^/]+\//);
      base = m ? m[0] : '/';
    }
    this.base = base;
  }
  async call<T>(op: string, args?: Record<string, unknown>, method?: 'GET' | 'POST'): Promise<T> {
    const m = method ?? (args === undefined ? 'GET' : 'POST');
    let url = `${this.base}api/${op}`;
    const init: RequestInit = { method: m, headers: {} };
    if (m === 'GET' && args) {
      const q = new URLSearchParams(Object.entries(args).map(([k, v]) => [k, String(v)]));
      url += `?${q}`;
    } else if (m === 'POST') {
      init.body = toJson(args ?? {});
      (init.headers as Record<string, string>)['Content-Type'] = 'application/json';
    }
    let res: Response;
    try {
      res = await fetch(url, init);
    } catch (e) {
      throw new ApiError(`the editor server does not answer (${(e as Error).message})`, 0, 'Network');
    }
    let body: unknown = null;
    try {
      body = fromJson(await res.text());
    } catch {
      body = null;
    }
    if (!res.ok) {
      const err = (body as { error?: { message?: string; kind?: string; errors?: ValidationError[] } } | null)?.error;
      throw new ApiError(err?.message ?? `${res.status} ${res.statusText}`, res.status, err?.kind ?? 'Error', Array.isArray(err?.errors) ? err!.errors : []);
    }
    return body as T;
  }
  fileUrl(url: string): string {
    if (/^(data:|https?:|\/)/.test(url)) return url;
    return this.base + url.replace(/^\.?\//, '');
  }
}

interface WidgetModel {
  send(msg: unknown): void;
  on(event: string, cb: (msg: unknown) => void): void;
  off?(event: string, cb?: (msg: unknown) => void): void;
}

export class WidgetTransport implements Transport {
  private model: WidgetModel;
  private next = 1;
  private pending = new Map<number, { resolve: (v: unknown) => void; reject: (e: Error) => void }>();
  constructor(model: WidgetModel) {
    this.model = model;
    model.on('msg:custom', (msg: unknown) => {
      const m = msg as { id?: number; ok?: boolean; result?: unknown; error?: { message?: string; kind?: string; status?: number; errors?: ValidationError[] } | string };
      if (typeof m?.id !== 'number') return;
      const p = this.pending.get(m.id);
      if (!p) return;
      this.pending.delete(m.id);
      if (m.ok) p.resolve(m.result);
      else {
        const e = typeof m.error === 'string' ? { message: m.error } : (m.error ?? {});
        p.reject(new ApiError(e.message ?? 'error', e.status ?? 400, e.kind ?? 'Error', Array.isArray(e.errors) ? e.errors : []));
      }
    });
  }
  call<T>(op: string, args?: Record<string, unknown>): Promise<T> {
    const id = this.next++;
    // the HTTP routes run/<id>[/cancel|/signal] are the service's status/cancel/signal
    const m = op.match(/^run\/([^/]+)(?:\/(cancel|signal))?$/);
    if (m) {
      args = { ...(args ?? {}), run: m[1] };
      op = m[2] ?? 'status';
    }
    return new Promise<T>((resolve, reject) => {
      this.pending.set(id, { resolve: resolve as (v: unknown) => void, reject });
      this.model.send({ id, op, args: args ?? {} });
    });
  }
  fileUrl(url: string): string {
    return url;
  }
}

/** Where the document in the page came from: a file under the server's folder (with the
 * revision it had when loaded or last saved), a built-in case study, or neither. */
export interface FileRef {
  path: string | null;
  builtin: string | null;
  revision: string | null;
}

export interface SaveArgs {
  path: string;
  document: Doc;
  revision: string | null;
  draft: boolean;
  origin?: string;
  create?: boolean;
}

/** The `save` request for writing the page's document to `path` (API.md). Saving over the
 * file it was loaded from sends that file's revision (a change on disk since then is a 409);
 * saving elsewhere ("save as", or a built-in's first save) sends `origin`, the built-in or
 * the file it came from, so the new file keeps that one's comments and forms. `force`
 * (overwrite after a 409) sends no revision. */
export function saveRequest(file: FileRef, path: string, document: Doc, opts: { force?: boolean; draft: boolean }): SaveArgs {
  const same = file.path !== null && file.path === path && file.builtin === null;
  const origin = file.builtin ?? (file.path !== null && !same ? file.path : null);
  return {
    path,
    document,
    revision: same && !opts.force ? file.revision : null,
    draft: opts.draft,
    ...(origin !== null ? { origin } : {}),
    // saving to another path never replaces a file there unless told to (force)
    ...(!same && !opts.force ? { create: true } : {}),
  };
}

/** The operations of API.md, typed. */
export class Api {
  t: Transport;
  constructor(t: Transport) {
    this.t = t;
  }
  palette() {
    return this.t.call<Palette>('palette');
  }
  files() {
    return this.t.call<FileList>('files');
  }
  load(args: { path?: string; builtin?: string }) {
    return this.t.call<Loaded>('load', args, 'POST');
  }
  validate(document: Doc, path?: string | null) {
    return this.t.call<Validation>('validate', path ? { document, path } : { document }, 'POST');
  }
  save(args: SaveArgs) {
    return this.t.call<{ path: string; revision: string; draft: boolean }>('save', { ...args }, 'POST');
  }
  newDocument() {
    return this.t.call<Loaded>('new');
  }
  run(args: { document: Doc; backend: string; t_final?: Json; dt?: Json; figures?: boolean }) {
    return this.t.call<{ run: string }>('run', args, 'POST');
  }
  runStatus(run: string) {
    return this.t.call<RunStatus>(`run/${run}`);
  }
  cancel(run: string) {
    return this.t.call<unknown>(`run/${run}/cancel`, {}, 'POST');
  }
  signal(run: string, name: string) {
    return this.t.call<SignalData>(`run/${run}/signal`, { name }, 'GET');
  }
  live(document: Doc) {
    return this.t.call<{ url: string }>('live', { document }, 'POST');
  }
  export(document: Doc, format: 'python' | 'svg' | 'png') {
    return this.t.call<{ text?: string; data_url?: string }>('export', { document, format }, 'POST');
  }
}
