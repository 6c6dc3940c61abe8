// The right panel: Properties, Problems, Run, Tune.

import type { ReactNode } from 'react';

export type Tab = 'props' | 'problems' | 'run' | 'tune';

export function Side({ tab, setTab, problems, children }: { tab: Tab; setTab: (t: Tab) => void; problems: number; children: ReactNode }) {
  return (
    <aside className="side">
      <div className="tabs">
        <button className={tab === 'props' ? 'on' : ''} onClick={() => setTab('props')}>
          Properties
        </button>
        <button className={tab === 'problems' ? 'on' : ''} onClick={() => setTab('problems')} data-testid="tab-problems">
          Problems {problems ? <span className="badge">{problems}</span> : null}
        </button>
        <button className={tab === 'run' ? 'on' : ''} onClick={() => setTab('run')} data-testid="tab-run">
          Run
        </button>
        <button className={tab === 'tune' ? 'on' : ''} onClick={() => setTab('tune')} data-testid="tab-tune">
          Tune
        </button>
      </div>
      <div className="side-body">{children}</div>
    </aside>
  );
}
