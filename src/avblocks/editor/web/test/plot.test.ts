import { describe, expect, it } from 'vitest';
import { signalLines } from '../src/ui/PlotPanel';

describe('signal plot lines', () => {
  const t = [0, 1, 2];
  it('draws one agent’s components of an (N, k) signal', () => {
    // 2 agents x 3 components; agent a, component j at time i = 100a + 10j + i
    const values = t.map((i) => [0, 1].map((a) => [0, 1, 2].map((j) => 100 * a + 10 * j + i)));
    const lines = signalLines({ t, values, labels: ['x', 'y', 'theta'] }, 1);
    expect(lines.map((l) => l.label)).toEqual(['x', 'y', 'theta']);
    expect(lines[2].ys).toEqual([120, 121, 122]);
  });
  it('draws the first 8 agents of an (N,) signal and a scalar as one line', () => {
    const values = t.map((i) => Array.from({ length: 10 }, (_, a) => a + i));
    const lines = signalLines({ t, values }, 0);
    expect(lines).toHaveLength(8);
    expect(lines[7]).toEqual({ label: 'agent 7', ys: [7, 8, 9] });
    expect(signalLines({ t, values: [1, 2, 3] }, 0)).toEqual([{ label: 'value', ys: [1, 2, 3] }]);
  });
});
