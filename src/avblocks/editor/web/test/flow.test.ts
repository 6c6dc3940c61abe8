import { describe, expect, it } from 'vitest';
import { stableFlow, toFlow } from '../src/flow';
import { moveItems } from '../src/model';
import type { Doc } from '../src/types';

// two teams (fleet -> drive -> fleet), with positions
function doc(): Doc {
  return {
    name: 'two',
    blocks: {
      f0: { type: 'vehicles.Unicycle' },
      d0: { type: 'controllers.PointToPoint' },
      f1: { type: 'vehicles.Unicycle' },
      d1: { type: 'controllers.PointToPoint' },
    },
    wires: [
      ['f0.pose', 'd0.pose'],
      ['d0.cmd', 'f0.cmd'],
      ['f1.pose', 'd1.pose'],
      ['d1.cmd', 'f1.cmd'],
    ],
    editor: { layout: { f0: [0, 0], d0: [300, 0], f1: [0, 200], d1: [300, 200] } },
  } as unknown as Doc;
}

describe('stableFlow: unchanged nodes and edges keep their objects', () => {
  it('the same flow again gives back the previous arrays themselves', () => {
    const a = toFlow(doc(), null);
    const b = stableFlow(a, toFlow(doc(), null));
    expect(b.nodes).toBe(a.nodes);
    expect(b.edges).toBe(a.edges);
  });

  it('moving one block renews that node only (and no edge: wires follow from handles)', () => {
    const d = doc();
    const a = toFlow(d, null);
    const b = stableFlow(a, toFlow(moveItems(d, { d1: [320, 240] }), null));
    const renewed = b.nodes.filter((n, i) => n !== a.nodes[i]).map((n) => n.id);
    expect(renewed).toEqual(['d1']);
    expect(b.nodes.find((n) => n.id === 'd1')!.position).toEqual({ x: 320, y: 240 });
    expect(b.edges).toBe(a.edges);
  });

  it('a check naming one port renews that block and the wire it is about, nothing else', () => {
    const d = doc();
    const a = toFlow(d, null);
    const validation = {
      ok: false,
      errors: [{ kind: 'ShapeError', message: 'pose: expected (N, 3)', block: 'd0', port: 'pose', wire: ['f0.pose', 'd0.pose'] as [string, string] }],
      signals: {},
    };
    const b = stableFlow(a, toFlow(d, null, { validation }));
    expect(b.nodes.filter((n, i) => n !== a.nodes[i]).map((n) => n.id)).toEqual(['d0']);
    expect(b.edges.filter((e, i) => e !== a.edges[i]).map((e) => e.id)).toEqual(['f0.pose->d0.pose']);
    const e = b.edges.find((x) => x.id === 'f0.pose->d0.pose')!;
    expect(e.data.errors).toEqual(['pose: expected (N, 3)']);
  });

  it('selection renews the selected node only', () => {
    const d = doc();
    const a = toFlow(d, null);
    const b = stableFlow(a, toFlow(d, null, { selected: new Set(['f1']) }));
    expect(b.nodes.filter((n, i) => n !== a.nodes[i]).map((n) => n.id)).toEqual(['f1']);
    expect(b.nodes.find((n) => n.id === 'f1')!.selected).toBe(true);
  });
});
