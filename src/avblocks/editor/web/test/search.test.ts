// Palette search: name first, then the words of a summary, then synonyms.
import { describe, expect, it } from 'vitest';
import { nameWords, score, search, terms } from '../src/search';
import type { BlockDecl } from '../src/types';

const b = (type: string, summary: string): BlockDecl => ({ type, name: type.split('.').pop()!, summary, inputs: [], outputs: [], params: [] });
const PALETTE = [
  b('vehicles.Unicycle', 'N first-order unicycles (paper eq. 1) in one block.'),
  b('controllers.PointToPoint', 'Drives N unicycles, each through its own list of waypoints.'),
  b('controllers.HolonomicPointToPoint', 'Drives N holonomic agents through their waypoints.'),
  b('controllers.LeaderFollower', 'Leader-follower formations (chains and trees) of N unicycles in one block.'),
  b('controllers.Flocking', 'Olfati-Saber flocking (alpha-lattice) for N double integrators.'),
  b('controllers.CollisionAvoidance', 'CBF safety filter for N single integrators (or off-axis points).'),
  b('tasks.NavigationLaw', "The navigation task's scripted controller: goal attraction plus repulsion."),
  b('blocks.Gain', '`y = k * u` (elementwise, `k` broadcast against `u`).'),
];
const types = (q: string) => search(PALETTE, q).map((x) => x.type.split('.').pop());

describe('search', () => {
  it('splits names into words and keeps phrases with synonyms whole', () => {
    expect(nameWords('PointToPoint')).toBe('point to point');
    expect(nameWords('CBFSafety')).toBe('cbf safety');
    expect(terms('go to the goal')).toEqual(['go to', 'goal']);
    expect(terms('to')).toEqual(['to']); // only stop words: kept
  });

  it('ranks a name match above a summary word above a synonym', () => {
    // "goal": a word of NavigationLaw's summary, a synonym for PointToPoint's waypoints
    expect(types('goal')).toEqual(['NavigationLaw', 'PointToPoint', 'HolonomicPointToPoint']);
    expect(types('go to')[0]).toBe('PointToPoint');
    expect(types('leader')[0]).toBe('LeaderFollower');
    expect(types('follow')[0]).toBe('LeaderFollower');
    expect(types('swarm')).toContain('Flocking');
    expect(types('avoid')[0]).toBe('CollisionAvoidance');
    expect(types('point')[0]).toBe('PointToPoint'); // its name starts so
    expect(types('Unicycle')[0]).toBe('Unicycle'); // the name itself first
    expect(types('unicycle first')).toEqual(['Unicycle']); // every word must match
  });

  it('finds summary words of code text, nothing for nonsense, all for an empty query', () => {
    expect(types('elementwise')).toEqual(['Gain']);
    expect(types('qwertyuiop')).toEqual([]);
    expect(search(PALETTE, '  ')).toHaveLength(PALETTE.length);
    expect(score(PALETTE[0], 'goals')).toBe(0);
    expect(types('goals')[0]).toBe('PointToPoint'); // a plural finds the synonyms of its singular
  });
});
