// Automatic layout with elkjs: layered, left to right, ports fixed on the sides.

import type { ELK as Elk } from 'elkjs/lib/elk.bundled.js';
import type { Doc, Palette, XY } from './types';
import { groupsOf, itemsAt, moveItems } from './model';
import { HEADER_H, ROW_H, toFlow } from './flow';

// elkjs is most of the bundle (1.6 of 1.9 MB): the page loads it the first time something
// is laid out (a file without positions, the Layout button), not with every diagram
let elkP: Promise<Elk> | null = null;
function getElk(): Promise<Elk> {
  elkP ??= import('elkjs/lib/elk.bundled.js').then((m) => new m.default());
  return elkP;
}

const OPTIONS: Record<string, string> = {
  'elk.algorithm': 'layered',
  'elk.direction': 'RIGHT',
  'elk.portConstraints': 'FIXED_ORDER',
  'elk.layered.spacing.nodeNodeBetweenLayers': '90',
  'elk.spacing.nodeNode': '40',
  'elk.layered.nodePlacement.strategy': 'BRANDES_KOEPF',
  'elk.layered.crossingMinimization.strategy': 'LAYER_SWEEP',
  'elk.edgeRouting': 'ORTHOGONAL',
  // room between layers and beside blocks for the wires the router draws round them
  'elk.layered.spacing.edgeNodeBetweenLayers': '24',
  'elk.spacing.edgeNode': '24',
  'elk.layered.feedbackEdges': 'true',
  'elk.separateConnectedComponents': 'true',
  'elk.spacing.componentComponent': '60',
};

/** Positions for the items shown at one level. */
export async function layoutLevel(doc: Doc, palette: Palette | null, level: string | null): Promise<Record<string, XY>> {
  const { nodes, edges } = toFlow(doc, palette, { level });
  const items = nodes.filter((n) => n.type !== 'boundary');
  if (!items.length) return {};
  const ids = new Set(items.map((n) => n.id));
  const graph = {
    id: 'root',
    layoutOptions: OPTIONS,
    children: items.map((n) => {
      const d = n.data as { inputs: { id: string }[]; outputs: { id: string }[] };
      return {
        id: n.id,
        width: n.width ?? 200,
        height: n.height ?? 60,
        // the ports where the canvas draws them (flow.portPoint), so layers line up with them
        layoutOptions: { 'elk.portConstraints': 'FIXED_POS' },
        ports: [
          ...d.inputs.map((p, i) => ({
            id: `${n.id}::in::${p.id}`,
            width: 1,
            height: 1,
            x: -1,
            y: HEADER_H + i * ROW_H + ROW_H / 2 + 4,
            layoutOptions: { 'elk.port.side': 'WEST' },
          })),
          ...d.outputs.map((p, i) => ({
            id: `${n.id}::out::${p.id}`,
            width: 1,
            height: 1,
            x: (n.width ?? 200),
            y: HEADER_H + i * ROW_H + ROW_H / 2 + 4,
            layoutOptions: { 'elk.port.side': 'EAST' },
          })),
        ],
      };
    }),
    edges: edges
      .filter((e) => ids.has(e.source) && ids.has(e.target))
      .map((e) => ({
        id: e.id,
        sources: [`${e.source}::out::${e.sourceHandle}`],
        targets: [`${e.target}::in::${e.targetHandle}`],
      })),
  };
  const out = await (await getElk()).layout(graph);
  const pos: Record<string, XY> = {};
  for (const c of out.children ?? []) pos[c.id] = [Math.round((c.x ?? 0) + 40), Math.round((c.y ?? 0) + 40)];
  return pos;
}

/** Lay out every level (the top and each group's inside). */
export async function layoutAll(doc: Doc, palette: Palette | null): Promise<Doc> {
  let d = doc;
  for (const level of [null, ...Object.keys(groupsOf(doc))]) {
    d = moveItems(d, await layoutLevel(d, palette, level));
  }
  return d;
}

/** True when some block or group has no position (most built-in files). */
export function needsLayout(doc: Doc): boolean {
  const layout = doc.editor?.layout ?? {};
  const groups = groupsOf(doc);
  return (
    Object.keys(doc.blocks).some((b) => !layout[b]) ||
    Object.values(groups).some((g) => !g.position) ||
    (Object.keys(doc.blocks).length > 0 && itemsAt(doc, null).blocks.length + itemsAt(doc, null).groups.length === 0)
  );
}
