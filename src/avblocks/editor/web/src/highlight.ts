// What the canvas shows on top of the document, changing with the pointer and the plot's time
// cursor: the wires lit (a hovered wire's net, every wire of a hovered port) and each plotted
// signal's value at the cursor's time. A small store outside React's state, so that hovering
// re-renders the few wires it changes, not the canvas (pure: no React here).

export interface WireKey {
  id: string;
  source: string;
  sourceHandle: string;
  target: string;
  targetHandle: string;
  /** the signal it carries ("block.port") */
  signal: string;
}

export interface WireMark {
  lit: boolean;
  hovered: boolean;
  /** The signal's value at the plot's cursor, as text (null: not plotted). */
  value: string | null;
}

const NONE: WireMark = { lit: false, hovered: false, value: null };

export class Highlight {
  private wires: WireKey[] = [];
  private byId = new Map<string, WireKey>();
  private marks = new Map<string, WireMark>();
  private subs = new Map<string, Set<() => void>>();
  private hoveredWire: string | null = null;
  private hoveredPort: { node: string; handle: string; side: 'in' | 'out' } | null = null;
  private values = new Map<string, string>();

  setWires(wires: WireKey[]) {
    this.wires = wires;
    this.byId = new Map(wires.map((w) => [w.id, w]));
    // (nothing lit, hovered or valued: nothing to redo; a drag changes wires every frame)
    if (this.marks.size || this.hoveredWire || this.hoveredPort || this.values.size) this.recompute();
  }

  hoverWire(id: string | null) {
    if (this.hoveredWire === id) return;
    this.hoveredWire = id;
    this.recompute();
  }

  hoverPort(p: { node: string; handle: string; side: 'in' | 'out' } | null) {
    const same = p && this.hoveredPort && p.node === this.hoveredPort.node && p.handle === this.hoveredPort.handle && p.side === this.hoveredPort.side;
    if (same || (!p && !this.hoveredPort)) return;
    this.hoveredPort = p;
    this.recompute();
  }

  /** Values at the cursor by signal name (empty: no cursor). */
  setValues(values: Map<string, string>) {
    this.values = values;
    this.recompute();
  }

  /** The wires lit now (their ids). */
  litWires(): string[] {
    return [...this.marks].filter(([, m]) => m.lit).map(([id]) => id);
  }

  private netOf(w: WireKey): string {
    return `${w.source}\u0000${w.sourceHandle}`;
  }

  private recompute() {
    const lit = new Set<string>();
    const nets = new Set<string>();
    if (this.hoveredWire) {
      const w = this.byId.get(this.hoveredWire);
      if (w) nets.add(this.netOf(w));
    }
    const p = this.hoveredPort;
    if (p) {
      for (const w of this.wires) {
        // an output: its whole net; an input: the wire into it and the rest of its driver's net
        if (p.side === 'out' && w.source === p.node && w.sourceHandle === p.handle) nets.add(this.netOf(w));
        if (p.side === 'in' && w.target === p.node && w.targetHandle === p.handle) nets.add(this.netOf(w));
      }
    }
    for (const w of this.wires) if (nets.has(this.netOf(w))) lit.add(w.id);
    const next = new Map<string, WireMark>();
    for (const w of this.wires) {
      const value = this.values.get(w.signal) ?? null;
      const m: WireMark = { lit: lit.has(w.id), hovered: w.id === this.hoveredWire, value };
      if (m.lit || m.hovered || m.value !== null) next.set(w.id, m);
    }
    const changed = new Set<string>();
    for (const [id, m] of next) {
      const o = this.marks.get(id);
      if (!o || o.lit !== m.lit || o.hovered !== m.hovered || o.value !== m.value) changed.add(id);
      else next.set(id, o);
    }
    for (const id of this.marks.keys()) if (!next.has(id)) changed.add(id);
    this.marks = next;
    for (const id of changed) for (const cb of this.subs.get(id) ?? []) cb();
  }

  get(id: string): WireMark {
    return this.marks.get(id) ?? NONE;
  }

  subscribe(id: string, cb: () => void): () => void {
    let s = this.subs.get(id);
    if (!s) this.subs.set(id, (s = new Set()));
    s.add(cb);
    return () => {
      s!.delete(cb);
      if (!s!.size) this.subs.delete(id);
    };
  }
}
