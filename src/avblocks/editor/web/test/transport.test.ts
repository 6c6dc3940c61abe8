import { afterEach, describe, expect, it, vi } from 'vitest';
import { Api, HttpTransport, saveRequest } from '../src/transport';
import type { FileRef } from '../src/transport';
import { emptyDocument } from '../src/model';

const doc = { ...emptyDocument(), name: 'team' };

describe('saveRequest (what Save and Save as send)', () => {
  const loaded: FileRef = { path: 'a/team.yaml', builtin: null, revision: 'r1' };

  it('saving over the loaded file sends its revision and no origin (a change on disk is a 409)', () => {
    expect(saveRequest(loaded, 'a/team.yaml', doc, { draft: false })).toEqual({ path: 'a/team.yaml', document: doc, revision: 'r1', draft: false });
  });

  it('save as another file sends the loaded file as origin and no revision', () => {
    const r = saveRequest(loaded, 'b/copy.yaml', doc, { draft: true });
    expect(r).toEqual({ path: 'b/copy.yaml', document: doc, revision: null, draft: true, origin: 'a/team.yaml', create: true });
  });

  it('save as another path never replaces a file there unless forced (create)', () => {
    expect(saveRequest(loaded, 'b/copy.yaml', doc, { draft: false }).create).toBe(true);
    expect('create' in saveRequest(loaded, 'b/copy.yaml', doc, { draft: false, force: true })).toBe(false);
    expect('create' in saveRequest(loaded, 'a/team.yaml', doc, { draft: false })).toBe(false);
  });

  it('a built-in case study is the origin of its first save, under any name', () => {
    const b: FileRef = { path: null, builtin: 'formation', revision: null };
    expect(saveRequest(b, 'formation.yaml', doc, { draft: false })).toMatchObject({ revision: null, origin: 'formation' });
    expect(saveRequest(b, 'x.yaml', doc, { draft: false }).origin).toBe('formation');
  });

  it('overwriting after a conflict sends no revision', () => {
    const r = saveRequest(loaded, 'a/team.yaml', doc, { draft: false, force: true });
    expect(r.revision).toBeNull();
    expect('origin' in r).toBe(false);
  });

  it('a new diagram has no origin and no revision', () => {
    const r = saveRequest({ path: null, builtin: null, revision: null }, 'new.yaml', doc, { draft: false });
    expect(r).toEqual({ path: 'new.yaml', document: doc, revision: null, draft: false, create: true });
  });
});

describe('HttpTransport', () => {
  afterEach(() => vi.unstubAllGlobals());

  it("posts save's arguments, origin included, as JSON to <token>/api/save", async () => {
    const sent: { url: string; init: RequestInit }[] = [];
    vi.stubGlobal('fetch', async (url: string, init: RequestInit) => {
      sent.push({ url, init });
      return new Response(JSON.stringify({ path: 'b/copy.yaml', revision: 'r2', draft: false }), { status: 200, headers: { 'Content-Type': 'application/json' } });
    });
    const api = new Api(new HttpTransport('/tok123/'));
    const r = await api.save(saveRequest({ path: 'a/team.yaml', builtin: null, revision: 'r1' }, 'b/copy.yaml', doc, { draft: false }));
    expect(r.revision).toBe('r2');
    expect(sent).toHaveLength(1);
    expect(sent[0].url).toBe('/tok123/api/save');
    expect(sent[0].init.method).toBe('POST');
    expect(JSON.parse(sent[0].init.body as string)).toEqual({ path: 'b/copy.yaml', document: doc, revision: null, draft: false, origin: 'a/team.yaml', create: true });
  });

  it('a 409 answer is an ApiError with status 409 and the server message', async () => {
    vi.stubGlobal('fetch', async () => new Response(JSON.stringify({ error: { message: 'the file changed on disk since it was loaded', kind: 'Conflict' } }), { status: 409, headers: { 'Content-Type': 'application/json' } }));
    const api = new Api(new HttpTransport('/t/'));
    await expect(api.save(saveRequest({ path: 'a.yaml', builtin: null, revision: 'old' }, 'a.yaml', doc, { draft: false }))).rejects.toMatchObject({ status: 409, kind: 'Conflict', message: 'the file changed on disk since it was loaded' });
  });
});
