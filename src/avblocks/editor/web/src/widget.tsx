// anywidget entry: export default { render({ model, el }) }; the same editor talking through the kernel.
import { createRoot } from 'react-dom/client';
import flowCss from '@xyflow/react/dist/style.css?inline';
import appCss from './styles.css?inline';
import { App } from './App';
import { WidgetTransport } from './transport';

interface Model {
  send(msg: unknown): void;
  on(event: string, cb: (msg: unknown) => void): void;
  get?(key: string): unknown;
}

function render({ model, el }: { model: Model; el: HTMLElement }) {
  const style = document.createElement('style');
  style.textContent = `${flowCss}\n${appCss}`;
  el.appendChild(style);
  const host = document.createElement('div');
  host.className = 'av-widget';
  const h = model.get?.('height');
  host.style.height = typeof h === 'number' ? `${h}px` : '640px';
  el.appendChild(host);
  const root = createRoot(host);
  root.render(<App transport={new WidgetTransport(model)} />);
  return () => root.unmount();
}

export default { render };
export { render };
