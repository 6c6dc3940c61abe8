import { createRoot } from 'react-dom/client';
import '@xyflow/react/dist/style.css';
import './styles.css';
import { App } from './App';
import { HttpTransport } from './transport';

createRoot(document.getElementById('root')!).render(<App transport={new HttpTransport()} />);
