// The canvas: the breadcrumb of subsystems, React Flow drawing the flow (controlled: the
// document is the app's), the minimap and zoom buttons, the plot panel, the messages.

import { Background, Controls, MiniMap, ReactFlow, SelectionMode } from '@xyflow/react';
import type { Connection, Edge, EdgeChange, Node, NodeChange } from '@xyflow/react';
import type { ReactNode } from 'react';
import type { Doc } from '../types';
import type { FlowEdge, FlowNode } from '../flow';
import { edgeTypes, nodeTypes } from '../nodes';
import type { Highlight } from '../highlight';

export interface Toast {
  id: number;
  text: string;
  kind: 'info' | 'warn' | 'error';
}

/** A node's colour in the minimap (one function for every render: the minimap's nodes stay memoised). */
function miniColor(n: Node): string {
  const f = n as unknown as FlowNode;
  if (f.type === 'subsystem') return '#c7d2fe';
  // red when the block, or one of its ports, has an error (as the block's own mark on the canvas)
  const d = f.data as { errors?: string[]; inputs?: { errors: string[] }[]; outputs?: { errors: string[] }[] } | undefined;
  const bad = !!d && (!!d.errors?.length || [...(d.inputs ?? []), ...(d.outputs ?? [])].some((p) => p.errors.length > 0));
  return bad ? '#f87171' : '#cbd5e1';
}

export function Canvas({
  doc,
  flow,
  path,
  detail,
  highlight,
  toasts,
  plot,
  edits,
  onEdgeClick,
  onPaneClick,
  onFit,
}: {
  doc: Doc;
  flow: { nodes: FlowNode[]; edges: FlowEdge[] };
  path: string[];
  detail: number;
  highlight: Highlight;
  toasts: Toast[];
  plot: ReactNode;
  edits: {
    onNodesChange: (c: NodeChange[]) => void;
    onEdgesChange: (c: EdgeChange[]) => void;
    onConnect: (c: Connection) => void;
    isValidConnection: (c: Connection | Edge) => boolean;
    onNodeDragStart: () => void;
    onDrop: (e: React.DragEvent) => void;
    openGroup: (g: string) => void;
    leaveTo: (depth: number) => void;
  };
  onEdgeClick: (e: React.MouseEvent, edge: Edge) => void;
  onPaneClick: () => void;
  onFit: () => void;
}) {
  return (
    <div
      className={`canvas ${detail >= 1 ? 'far' : ''} ${detail >= 2 ? 'tiny' : ''}`}
      onDragOver={(e) => {
        e.preventDefault();
        e.dataTransfer.dropEffect = 'copy';
      }}
      onDrop={edits.onDrop}
    >
      <div className="breadcrumb">
        <button className={path.length ? 'link' : 'here'} onClick={() => edits.leaveTo(0)}>
          {doc.name || 'diagram'}
        </button>
        {path.map((g, i) => (
          <span key={g}>
            {' › '}
            <button className={i === path.length - 1 ? 'here' : 'link'} onClick={() => edits.leaveTo(i + 1)}>
              {doc.editor?.groups?.[g]?.label ?? g}
            </button>
          </span>
        ))}
      </div>
      <ReactFlow
        nodes={flow.nodes as Node[]}
        edges={flow.edges as unknown as Edge[]}
        nodeTypes={nodeTypes}
        edgeTypes={edgeTypes}
        onNodesChange={edits.onNodesChange}
        onEdgesChange={edits.onEdgesChange}
        onConnect={edits.onConnect}
        isValidConnection={edits.isValidConnection}
        onNodeDragStart={edits.onNodeDragStart}
        onNodeDoubleClick={(_, n) => {
          if (n.type === 'subsystem') edits.openGroup(n.id);
        }}
        onEdgeClick={onEdgeClick}
        // (not while a button is down: panning or dragging across wires)
        onEdgeMouseEnter={(ev, e) => {
          if (!ev.buttons) highlight.hoverWire(e.id);
        }}
        onEdgeMouseLeave={() => highlight.hoverWire(null)}
        onPaneClick={onPaneClick}
        deleteKeyCode={null}
        selectionKeyCode="Shift"
        multiSelectionKeyCode={['Meta', 'Control', 'Shift']}
        selectionMode={SelectionMode.Partial}
        minZoom={0.05}
        maxZoom={3}
        defaultViewport={{ x: 0, y: 0, zoom: 1 }}
        onlyRenderVisibleElements
        proOptions={{ hideAttribution: true }}
        defaultEdgeOptions={{ type: 'wire' }}
        connectionRadius={24}
      >
        <Background gap={20} size={1} color="#d4d8de" />
        <MiniMap pannable zoomable nodeStrokeWidth={2} nodeColor={miniColor} />
        <Controls showInteractive={false} onFitView={onFit} />
      </ReactFlow>
      {!Object.keys(doc.blocks).length ? (
        <div className="empty-hint">
          <div className="big">Drag a block from the palette</div>
          <div>
            or press <kbd>/</kbd>, type its name and <kbd>Enter</kbd>. Wire an output (right) to an input (left). <kbd>?</kbd> lists the shortcuts.
          </div>
        </div>
      ) : null}
      {plot}
      <div className="toasts">
        {toasts.map((t) => (
          <div key={t.id} className={`toast ${t.kind}`} data-testid="toast">
            {t.text}
          </div>
        ))}
      </div>
    </div>
  );
}
