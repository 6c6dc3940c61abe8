import { describe, expect, it } from 'vitest';
import {
  addBlock,
  commit,
  connect,
  copyItems,
  disconnect,
  emptyDocument,
  groupItems,
  groupPorts,
  history,
  itemsAt,
  ModelError,
  moveItems,
  parseValue,
  paste,
  portsOf,
  redo,
  removeItems,
  renameBlock,
  setDiagramParameter,
  setParam,
  undo,
  ungroup,
  valueToText,
  generatorOf,
  defaultNameFor,
} from '../src/model';
import { toFlow, handleRef, IN_NODE, OUT_NODE } from '../src/flow';
import { layoutAll, needsLayout } from '../src/layout';
import type { Doc, Palette } from '../src/types';

const palette: Palette = {
  families: [
    {
      name: 'vehicles',
      title: 'Vehicles',
      blocks: [
        {
          type: 'vehicles.Unicycle',
          name: 'Unicycle',
          inputs: [{ name: 'cmd', shape: '(N, 2)' }],
          outputs: [{ name: 'pose', shape: '(N, 3)' }],
          params: [],
          template: { pose0: { random_poses: { n: '$agents', area: [50, 50], seed: '$seed' } } },
        },
      ],
    },
    {
      name: 'controllers',
      title: 'Controllers',
      blocks: [
        {
          type: 'controllers.PointToPoint',
          name: 'PointToPoint',
          inputs: [{ name: 'pose', shape: '(N, 3)' }],
          outputs: [{ name: 'cmd', shape: '(N, 2)' }],
          params: [],
        },
      ],
    },
  ],
  generators: [{ name: 'random_poses', args: [] }],
};

/** fleet -> drive -> fleet, the two-block loop of the API example. */
function loop(): Doc {
  let d = emptyDocument('t');
  d = addBlock(d, 'vehicles.Unicycle', { name: 'fleet', position: [0, 0] }).doc;
  d = addBlock(d, 'controllers.PointToPoint', { name: 'drive', position: [300, 0] }).doc;
  d = connect(d, 'fleet.pose', 'drive.pose').doc;
  d = connect(d, 'drive.cmd', 'fleet.cmd').doc;
  return d;
}

describe('blocks', () => {
  it('adds a block with its template and a fresh snake_case name', () => {
    const d0 = emptyDocument();
    const tmpl = palette.families[0].blocks[0].template!;
    const { doc: d1, name } = addBlock(d0, 'vehicles.Unicycle', { template: tmpl, position: [10.4, 20.6] });
    expect(name).toBe('unicycle');
    expect(d1.blocks.unicycle).toEqual({ type: 'vehicles.Unicycle', ...tmpl });
    expect(d1.editor!.layout!.unicycle).toEqual([10, 21]);
    // the template is copied, not shared
    (d1.blocks.unicycle.pose0 as Record<string, unknown>).x = 1;
    expect(tmpl.pose0).not.toHaveProperty('x');
    const { name: second } = addBlock(d1, 'vehicles.Unicycle');
    expect(second).toBe('unicycle2');
    expect(d0.blocks).toEqual({}); // the input document is unchanged
  });

  it('derives names from CamelCase types', () => {
    expect(defaultNameFor('controllers.PointToPoint')).toBe('point_to_point');
    expect(defaultNameFor('environment.APFField')).toBe('apf_field');
  });

  it('removes blocks with their wires and positions', () => {
    const d = removeItems(loop(), ['drive']);
    expect(Object.keys(d.blocks)).toEqual(['fleet']);
    expect(d.wires).toEqual([]);
    expect(d.editor!.layout).toEqual({ fleet: [0, 0] });
  });

  it('renames a block everywhere it is named, keeping key order', () => {
    let d = loop();
    d = { ...d, simulation: { ...d.simulation, log: ['fleet.pose', 'drive.cmd'] } };
    d = groupItems(d, ['drive'], { name: 'ctl' }).doc;
    const r = renameBlock(d, 'fleet', 'robots');
    expect(Object.keys(r.blocks)).toEqual(['robots', 'drive']);
    expect(r.wires).toEqual([
      ['robots.pose', 'drive.pose'],
      ['drive.cmd', 'robots.cmd'],
    ]);
    expect(r.editor!.layout!.robots).toEqual([0, 0]);
    expect(r.simulation!.log).toEqual(['robots.pose', 'drive.cmd']);
    const r2 = renameBlock(r, 'drive', 'p2p');
    expect(r2.editor!.groups!.ctl.blocks).toEqual(['p2p']);
    expect(() => renameBlock(d, 'fleet', 'drive')).toThrow(ModelError);
    expect(() => renameBlock(d, 'fleet', '2x')).toThrow(/not a valid name/);
  });

  it('sets and removes parameters', () => {
    let d = setParam(loop(), 'drive', 'gain', 2.5);
    expect(d.blocks.drive.gain).toBe(2.5);
    d = setParam(d, 'drive', 'gain', undefined);
    expect(d.blocks.drive).not.toHaveProperty('gain');
    expect(() => setParam(d, 'drive', 'type', 'x')).toThrow(ModelError);
    d = setDiagramParameter(d, 'agents', 300);
    expect(d.parameters).toEqual({ agents: 300, seed: 1 });
  });
});

describe('wires', () => {
  it('keeps one driver per input: a second wire into an input replaces the first', () => {
    let d = loop();
    d = addBlock(d, 'vehicles.Unicycle', { name: 'other' }).doc;
    const r = connect(d, 'other.pose', 'drive.pose');
    expect(r.replaced).toEqual(['fleet.pose', 'drive.pose']);
    expect(r.doc.wires.filter(([, b]) => b === 'drive.pose')).toEqual([['other.pose', 'drive.pose']]);
    expect(r.doc.wires).toHaveLength(2);
    // an output may drive many inputs
    const fan = connect(loop(), 'fleet.pose', 'fleet.cmd');
    expect(fan.doc.wires.filter(([a]) => a === 'fleet.pose')).toHaveLength(2);
    // the same wire again changes nothing
    const same = connect(loop(), 'fleet.pose', 'drive.pose');
    expect(same.added).toBe(false);
    expect(same.doc).toBe(same.doc);
    expect(() => connect(loop(), 'nobody.y', 'drive.pose')).toThrow(/no block named 'nobody'/);
  });

  it('disconnects', () => {
    const d = disconnect(loop(), ['fleet.pose', 'drive.pose']);
    expect(d.wires).toEqual([['drive.cmd', 'fleet.cmd']]);
  });
});

describe('groups', () => {
  function four(): Doc {
    let d = loop();
    d = addBlock(d, 'controllers.PointToPoint', { name: 'mon', position: [600, 0] }).doc;
    d = connect(d, 'fleet.pose', 'mon.pose').doc;
    return d;
  }

  it('derives a group ports from the wires its boundary cuts', () => {
    const { doc, name } = groupItems(four(), ['drive', 'mon'], { label: 'Control' });
    expect(name).toBe('group');
    expect(groupPorts(doc, name)).toEqual({ inputs: ['drive.pose', 'mon.pose'], outputs: ['drive.cmd'] });
    expect(itemsAt(doc, null)).toEqual({ blocks: ['fleet'], groups: ['group'] });
    expect(itemsAt(doc, 'group')).toEqual({ blocks: ['drive', 'mon'], groups: [] });
    expect(doc.editor!.groups!.group.position).toEqual([450, 0]);
    // the runnable diagram is unchanged: same blocks, same wires
    expect(doc.blocks).toEqual(four().blocks);
    expect(doc.wires).toEqual(four().wires);
  });

  it('draws a group as one node with its derived handles, and the inside with boundary nodes', () => {
    const { doc } = groupItems(four(), ['drive', 'mon']);
    const top = toFlow(doc, palette);
    expect(top.nodes.map((n) => n.id).sort()).toEqual(['fleet', 'group']);
    const edges = top.edges.map((e) => [e.source, e.sourceHandle, e.target, e.targetHandle]);
    expect(edges).toEqual([
      ['fleet', 'pose', 'group', 'drive.pose'],
      ['group', 'drive.cmd', 'fleet', 'cmd'],
      ['fleet', 'pose', 'group', 'mon.pose'],
    ]);
    // a wire drawn onto a group's handle means the inner port
    expect(handleRef(doc, 'group', 'drive.pose')).toBe('drive.pose');
    expect(handleRef(doc, 'fleet', 'pose')).toBe('fleet.pose');
    const inside = toFlow(doc, palette, { level: 'group' });
    expect(inside.nodes.map((n) => n.id).sort()).toEqual([IN_NODE, OUT_NODE, 'drive', 'mon'].sort());
    const ie = inside.edges.map((e) => [e.source, e.sourceHandle, e.target, e.targetHandle]);
    expect(ie).toEqual([
      [IN_NODE, 'fleet.pose', 'drive', 'pose'],
      ['drive', 'cmd', OUT_NODE, 'drive.cmd'],
      [IN_NODE, 'fleet.pose', 'mon', 'pose'],
    ]);
  });

  it('nests groups and ungroups back to the same document', () => {
    const d0 = four();
    const g1 = groupItems(d0, ['drive', 'mon'], { name: 'inner' }).doc;
    const g2 = groupItems(g1, ['fleet', 'inner'], { name: 'outer' }).doc;
    expect(itemsAt(g2, null)).toEqual({ blocks: [], groups: ['outer'] });
    expect(itemsAt(g2, 'outer')).toEqual({ blocks: ['fleet'], groups: ['inner'] });
    expect(groupPorts(g2, 'outer')).toEqual({ inputs: [], outputs: [] });
    const u = ungroup(ungroup(g2, 'outer'), 'inner');
    expect(u.editor!.groups).toEqual({});
    expect(itemsAt(u, null).blocks.sort()).toEqual(['drive', 'fleet', 'mon']);
    // removing a group removes what it holds
    const r = removeItems(g1, ['inner']);
    expect(Object.keys(r.blocks)).toEqual(['fleet']);
    expect(r.wires).toEqual([]);
    expect(r.editor!.groups).toEqual({});
  });

  it('refuses to group items of different levels', () => {
    const g1 = groupItems(four(), ['drive'], { name: 'a' }).doc;
    expect(() => groupItems(g1, ['fleet', 'drive'])).toThrow(/different levels/);
  });
});

describe('copy and paste', () => {
  it('pastes with fresh names, the wires among the copied blocks renamed', () => {
    const d = loop();
    const frag = copyItems(d, ['fleet', 'drive']);
    const { doc, names } = paste(d, frag, [100, 50]);
    expect(names).toEqual(['fleet2', 'drive2']);
    expect(doc.wires).toEqual([
      ['fleet.pose', 'drive.pose'],
      ['drive.cmd', 'fleet.cmd'],
      ['fleet2.pose', 'drive2.pose'],
      ['drive2.cmd', 'fleet2.cmd'],
    ]);
    expect(doc.editor!.layout!.drive2).toEqual([400, 50]);
    expect(doc.blocks.fleet2).toEqual(d.blocks.fleet);
    // a wire to a block not copied is not pasted
    const one = paste(d, copyItems(d, ['drive']));
    expect(one.names).toEqual(['drive2']);
    expect(one.doc.wires).toHaveLength(2);
  });
});

describe('history', () => {
  it('undoes and redoes, and a new edit clears the redo list', () => {
    const d0 = emptyDocument();
    const d1 = addBlock(d0, 'vehicles.Unicycle').doc;
    const d2 = addBlock(d1, 'controllers.PointToPoint').doc;
    let h = commit(commit(history(d0), d1), d2);
    h = undo(h);
    expect(h.present).toBe(d1);
    h = undo(h);
    expect(h.present).toBe(d0);
    expect(undo(h)).toBe(h);
    h = redo(h);
    expect(h.present).toBe(d1);
    const d3 = setDiagramParameter(d1, 'agents', 300);
    h = commit(h, d3);
    expect(h.future).toEqual([]);
    expect(redo(h)).toBe(h);
  });

  it('merges edits of one field in a row into one step', () => {
    const d0 = emptyDocument();
    let h = history(d0);
    for (const v of [3, 30, 300]) h = commit(h, setDiagramParameter(h.present, 'agents', v), 'param:agents');
    expect(h.past).toHaveLength(1);
    expect(h.present.parameters!.agents).toBe(300);
    expect(undo(h).present.parameters!.agents).toBe(15);
  });

  it('keeps positions out of the runnable diagram', () => {
    const d = moveItems(loop(), { fleet: [12.7, 3.2] });
    expect(d.editor!.layout!.fleet).toEqual([13, 3]);
    expect(d.wires).toEqual(loop().wires);
  });
});

describe('values', () => {
  it('reads field text as JSON with bare $references and words', () => {
    expect(parseValue('3.5')).toBe(3.5);
    expect(parseValue('$agents')).toBe('$agents');
    expect(parseValue('[50, 50]')).toEqual([50, 50]);
    expect(parseValue('{n: $agents, area: [50, 50]}')).toEqual({ n: '$agents', area: [50, 50] });
    expect(parseValue('{"tree": star}')).toEqual({ tree: 'star' });
    expect(parseValue('[true, null, rk4]')).toEqual([true, null, 'rk4']);
    expect(parseValue('rk4')).toBe('rk4');
    expect(() => parseValue('[1, 2')).toThrow(ModelError);
    expect(() => parseValue('')).toThrow(ModelError);
    expect(() => parseValue('1 2')).toThrow(ModelError);
  });

  it('writes values back to the same text', () => {
    for (const t of ['{n: $agents, area: [50, 50]}', '[[12, 0], [42, 0]]', '$agents', '2.5']) {
      expect(valueToText(parseValue(t))).toBe(t);
    }
  });

  it('recognises generator forms', () => {
    expect(generatorOf({ random_poses: { n: 3 } }, ['random_poses'])).toEqual({ name: 'random_poses', args: { n: 3 } });
    expect(generatorOf({ random_poses: { n: 3 }, x: 1 }, ['random_poses'])).toBeNull();
    expect(generatorOf([1, 2], ['random_poses'])).toBeNull();
  });

  it('reads what YAML reads as NaN and infinity, and numbers too large, as those numbers', () => {
    // (the library judges them: the field shows its words, nothing typed is dropped)
    expect(parseValue('.nan')).toBeNaN();
    expect(parseValue('nan')).toBeNaN();
    expect(parseValue('1e999')).toBe(Infinity);
    expect(parseValue('-1e999')).toBe(-Infinity);
    expect(parseValue('.inf')).toBe(Infinity);
    expect(parseValue('-.inf')).toBe(-Infinity);
    expect(parseValue('[1, .nan, -.inf]')).toEqual([1, NaN, -Infinity]);
    expect(parseValue('{gain: 1e999}')).toEqual({ gain: Infinity });
    expect(valueToText(parseValue('[1, .nan, -.inf]'))).toBe('[1, .nan, -.inf]');
    expect(valueToText(Infinity)).toBe('.inf');
    expect(parseValue('infinite')).toBe('infinite'); // a word stays a word
  });
});

describe('flow view', () => {
  it('labels wires with their source shape and puts errors on port, node and wire', () => {
    const d = loop();
    const { nodes, edges } = toFlow(d, palette, {
      validation: {
        ok: false,
        errors: [
          { message: 'bad pose', block: 'drive', port: 'pose', wire: ['fleet.pose', 'drive.pose'] },
          { message: 'bad gain', block: 'drive', param: 'gain' },
        ],
        signals: { 'fleet.pose': { shape: '(15, 3)' } },
      },
    });
    const drive = nodes.find((n) => n.id === 'drive')!.data as import('../src/flow').BlockData;
    expect(drive.inputs[0]).toMatchObject({ id: 'pose', errors: ['bad pose'], driven: true });
    expect(drive.errors).toEqual(['bad gain']);
    const e = edges.find((x) => x.id === 'fleet.pose->drive.pose')!;
    expect(e.data.shape).toBe('(15, 3)');
    expect(e.data.errors).toEqual(['bad pose']);
    expect(edges.find((x) => x.id === 'drive.cmd->fleet.cmd')!.data.errors).toEqual([]);
  });

  it('shows ports that only wires or parameters name', () => {
    let d = addBlock(emptyDocument(), 'controllers.Supervisor', { name: 'sup', template: { inputs: { pose: [3, 3] }, outputs: { ref: {} } } }).doc;
    d = addBlock(d, 'vehicles.Unicycle', { name: 'fleet' }).doc;
    d = connect(d, 'fleet.pose', 'sup.extra').doc;
    expect(portsOf(d, 'sup', palette)).toEqual({ inputs: ['pose', 'extra'], outputs: ['ref'] });
    expect(portsOf(d, 'sup', palette, { sup: { inputs: ['pose', 'clock'], outputs: [] } }).inputs).toEqual(['pose', 'clock', 'extra']);
  });
});

describe('layout', () => {
  it('lays out a file without positions left to right along its wires', async () => {
    let d: Doc = { ...loop(), editor: {} };
    d = addBlock(d, 'controllers.PointToPoint', { name: 'mon' }).doc;
    d = connect(d, 'fleet.pose', 'mon.pose').doc;
    d = { ...d, editor: { layout: {}, groups: {} } };
    expect(needsLayout(d)).toBe(true);
    const out = await layoutAll(d, palette);
    expect(needsLayout(out)).toBe(false);
    const L = out.editor!.layout!;
    // every block placed, none overlapping
    const boxes = Object.values(L).map(([x, y]) => [x, y, x + 210, y + 66]);
    for (let i = 0; i < boxes.length; i++)
      for (let j = i + 1; j < boxes.length; j++) {
        const [a, b] = [boxes[i], boxes[j]];
        const overlap = a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
        expect(overlap).toBe(false);
      }
    // the loop fleet -> drive -> fleet is broken somewhere; mon is fed by fleet, so it sits right of it
    expect(L.mon[0]).toBeGreaterThan(L.fleet[0]);
  });
});
