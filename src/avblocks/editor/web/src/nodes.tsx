// Canvas pieces: block, group and boundary nodes, and the wire edge.

import { createContext, memo, useCallback, useContext, useSyncExternalStore } from 'react';
import { BaseEdge, EdgeLabelRenderer, getSmoothStepPath, Handle, Position } from '@xyflow/react';
import type { EdgeProps, NodeProps } from '@xyflow/react';
import type { BlockData, BoundaryData, EdgeData, GroupData, PortView } from './flow';
import { HEADER_H, ROW_H } from './flow';
import { Highlight } from './highlight';

/** The canvas's highlight store (highlight.ts), one per editor. */
export const HighlightContext = createContext<Highlight>(new Highlight());

function useMark(id: string) {
  const h = useContext(HighlightContext);
  const sub = useCallback((cb: () => void) => h.subscribe(id, cb), [h, id]);
  return useSyncExternalStore(sub, () => h.get(id));
}

/** Event a click on a wire's label sends (the canvas treats it as a click on the wire). */
export const WIRE_CLICK = 'avblocks:wire-click';

function family(type: string): string {
  return type.split('.')[0] ?? 'blocks';
}

function portTitle(p: PortView, dir: string): string {
  const lines = [`${dir} ${p.label}${p.shape ? `  ${p.shape}` : ''}${p.unit ? `  [${p.unit}]` : ''}`];
  if (p.doc) lines.push(p.doc);
  for (const e of p.errors) lines.push(`⚠ ${e}`);
  return lines.join('\n');
}

function Port({ p, side, index, node }: { p: PortView; side: 'in' | 'out'; index: number; node: string }) {
  const top = HEADER_H + index * ROW_H + ROW_H / 2 + 4;
  const bad = p.errors.length > 0;
  const title = portTitle(p, side === 'in' ? 'input' : 'output');
  const h = useContext(HighlightContext);
  return (
    <>
      <Handle
        onMouseEnter={(e) => {
          if (!e.buttons) h.hoverPort({ node, handle: p.id, side });
        }}
        onMouseLeave={() => h.hoverPort(null)}
        type={side === 'in' ? 'target' : 'source'}
        position={side === 'in' ? Position.Left : Position.Right}
        id={p.id}
        style={{ top }}
        className={`port-handle ${bad ? 'bad' : ''} ${p.driven ? 'driven' : ''}`}
        title={title}
        data-port={p.id}
        data-testid={`handle-${side}-${p.id}`}
      />
      <div
        className={`port-label ${side} ${bad ? 'bad' : ''}`}
        style={{ top: top - ROW_H / 2 }}
        title={title}
        data-port-label={p.id}
      >
        <span className="port-name">{p.label}</span>
        {p.shape ? <span className="port-shape">{p.shape}</span> : null}
      </div>
    </>
  );
}

export const BlockNode = memo(function BlockNode({ id, data, selected }: NodeProps) {
  const d = data as BlockData;
  const bad = d.errors.length > 0 || d.inputs.some((p) => p.errors.length) || d.outputs.some((p) => p.errors.length);
  const errTitle = [...d.errors, ...d.inputs.flatMap((p) => p.errors), ...d.outputs.flatMap((p) => p.errors)].join('\n');
  return (
    <div
      className={`av-node fam-${family(d.type)} ${selected ? 'selected' : ''} ${bad ? 'bad' : ''} ${d.known ? '' : 'unknown'}`}
      data-block={d.name}
      title={d.summary ? `${d.type}\n${d.summary}` : d.type}
    >
      <div className="av-node-head">
        <span className="av-node-title">{d.title}</span>
        <span className="av-node-name">{d.name}</span>
        {bad ? (
          <span className="av-node-err" title={errTitle} data-testid="node-error">
            !
          </span>
        ) : null}
      </div>
      {d.inputs.map((p, i) => (
        <Port key={`i-${p.id}`} p={p} side="in" index={i} node={id} />
      ))}
      {d.outputs.map((p, i) => (
        <Port key={`o-${p.id}`} p={p} side="out" index={i} node={id} />
      ))}
      {d.errors.length ? <div className="av-node-errline" title={errTitle}>{d.errors[0]}</div> : null}
    </div>
  );
});

export const GroupNode = memo(function GroupNode({ id, data, selected }: NodeProps) {
  const d = data as GroupData;
  const bad = d.errors.length > 0;
  return (
    <div className={`av-node av-group ${selected ? 'selected' : ''} ${bad ? 'bad' : ''}`} data-group={d.name} title="Double-click to open">
      <div className="av-node-head">
        <span className="av-node-title">▣ {d.label}</span>
        <span className="av-node-name">{d.count} block{d.count === 1 ? '' : 's'}</span>
        {bad ? (
          <span className="av-node-err" title={d.errors.join('\n')}>
            {d.errors.length}
          </span>
        ) : null}
      </div>
      {d.inputs.map((p, i) => (
        <Port key={`i-${p.id}`} p={p} side="in" index={i} node={id} />
      ))}
      {d.outputs.map((p, i) => (
        <Port key={`o-${p.id}`} p={p} side="out" index={i} node={id} />
      ))}
    </div>
  );
});

export const BoundaryNode = memo(function BoundaryNode({ id, data }: NodeProps) {
  const d = data as BoundaryData;
  return (
    <div className={`av-node av-boundary ${d.side}`}>
      <div className="av-node-head">
        <span className="av-node-title">{d.side === 'in' ? 'from outside' : 'to outside'}</span>
      </div>
      {d.ports.map((p, i) => (
        <Port key={p.id} p={p} side={d.side === 'in' ? 'out' : 'in'} index={i} node={id} />
      ))}
    </div>
  );
});

export const WireEdge = memo(function WireEdge(props: EdgeProps) {
  const { id, sourceX, sourceY, targetX, targetY, sourcePosition, targetPosition, selected, markerEnd } = props;
  const d = props.data as EdgeData;
  const mark = useMark(id);
  const r = d.route;
  // the routed path (routes.ts: around the blocks); until routed, React Flow's own
  const path = r ? r.d : getSmoothStepPath({ sourceX, sourceY, targetX, targetY, sourcePosition, targetPosition, borderRadius: 6, offset: 18 })[0];
  // the shape sits by the source port, as Simulink shows signal dimensions
  const lx = sourceX + 10;
  const ly = sourceY - 10;
  const bad = d.errors.length > 0;
  const cls = `av-wire ${bad ? 'bad' : ''} ${selected ? 'selected' : ''} ${mark.lit ? 'lit' : ''}`;
  const name = `${d.wire[0]} → ${d.wire[1]}`;
  return (
    <>
      <BaseEdge id={id} path={path} markerEnd={markerEnd} className={cls} interactionWidth={14} />
      {r?.dots.map((p, i) => (
        <circle key={i} cx={p[0]} cy={p[1]} r={3.5} className={`av-junction ${mark.lit ? 'lit' : ''}`} data-junction={`${p[0]},${p[1]}`} />
      ))}
      {d.shape || bad || mark.hovered || mark.value !== null ? (
        <EdgeLabelRenderer>
          {d.shape || bad ? (
            <div
              className={`av-wire-label ${bad ? 'bad' : ''} ${selected ? 'selected' : ''} ${mark.lit ? 'lit' : ''}`}
              style={{ transform: `translate(0, -50%) translate(${lx}px, ${ly}px)` }}
              onClick={(e) => window.dispatchEvent(new CustomEvent(WIRE_CLICK, { detail: { wire: d.wire, add: e.shiftKey } }))}
              title={[name, ...d.errors].join('\n')}
              data-wire={`${d.wire[0]}->${d.wire[1]}`}
            >
              {bad ? '⚠ ' : ''}
              {d.shape ?? ''}
            </div>
          ) : null}
          {mark.hovered && r ? (
            <div className="av-wire-name" style={{ transform: `translate(-50%, -130%) translate(${r.mid[0]}px, ${r.mid[1]}px)` }} data-wire-name={id}>
              {name}
              {d.shape ? <span className="muted"> {d.shape}</span> : null}
            </div>
          ) : null}
          {mark.value !== null ? (
            <div
              className="av-wire-value"
              style={{ transform: `translate(0, 50%) translate(${lx}px, ${sourceY + 4}px)` }}
              data-wire-value={d.wire[0]}
              title={`${d.wire[0]} at the plot's cursor`}
            >
              {mark.value}
            </div>
          ) : null}
        </EdgeLabelRenderer>
      ) : null}
    </>
  );
});

export const nodeTypes = { block: BlockNode, subsystem: GroupNode, boundary: BoundaryNode };
export const edgeTypes = { wire: WireEdge };
