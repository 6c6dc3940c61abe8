// Palette search (pure): by name, by the words of a block's summary, and by synonyms, ranked
// in that order. "goal" or "go to" finds PointToPoint, "swarm" finds Flocking.

import type { BlockDecl } from './types';

/** What people call a thing when they do not know the block's name: each word or phrase
 * (left) also looks for the words on the right, in block names and summaries. */
export const SYNONYMS: Record<string, string[]> = {
  goal: ['waypoint', 'point to point', 'target', 'reference'],
  'go to': ['waypoint', 'point to point', 'goal'],
  goto: ['waypoint', 'point to point'],
  reach: ['waypoint', 'point to point', 'goal'],
  destination: ['waypoint', 'point to point', 'goal'],
  waypoint: ['point to point', 'goal'],
  path: ['waypoint', 'point to point'],
  navigate: ['navigation', 'waypoint', 'point to point'],
  leader: ['leader follower', 'formation', 'follow'],
  follow: ['leader follower', 'tracking', 'tracker', 'pursuit'],
  follower: ['leader follower', 'formation'],
  track: ['tracking', 'tracker', 'follow'],
  chase: ['pursuit', 'chase', 'pursuers'],
  pursue: ['pursuit', 'chase'],
  swarm: ['flocking', 'consensus', 'formation', 'coverage'],
  flock: ['flocking', 'swarm'],
  herd: ['flocking', 'consensus'],
  boids: ['flocking'],
  rendezvous: ['consensus'],
  agree: ['consensus'],
  meet: ['consensus', 'rendezvous'],
  formation: ['leader follower', 'displacement formation', 'formation reference'],
  avoid: ['collision avoidance', 'collision', 'safety filter', 'obstacle'],
  avoidance: ['collision avoidance', 'safety filter'],
  obstacle: ['collision', 'world', 'range sensor'],
  crash: ['collision'],
  safety: ['collision avoidance', 'safety filter', 'cbf'],
  robot: ['unicycle', 'diff drive', 'differential drive'],
  car: ['ackermann', 'unicycle'],
  vehicle: ['unicycle', 'ackermann', 'diff drive', 'quadrotor'],
  drone: ['quadrotor', 'blimp'],
  uav: ['quadrotor', 'blimp'],
  quadcopter: ['quadrotor'],
  wheels: ['diff drive', 'differential drive'],
  camera: ['scene camera', 'vision', 'image'],
  lidar: ['range sensor'],
  sensor: ['range sensor', 'neighbors', 'target detection'],
  neighbour: ['neighbors'],
  neighbor: ['neighbors'],
  network: ['comm channel', 'gossip', 'broadcast'],
  communication: ['comm channel', 'gossip', 'broadcast', 'messages'],
  message: ['comm channel', 'gossip', 'broadcast'],
  plot: ['scope', 'animation'],
  graph: ['scope'],
  display: ['scope', 'animation'],
  animate: ['animation'],
  record: ['scope'],
  log: ['scope'],
  multiply: ['gain', 'product'],
  scale: ['gain'],
  add: ['sum'],
  subtract: ['sum'],
  clip: ['saturation'],
  limit: ['saturation', 'rate limiter'],
  delay: ['unit delay', 'zero order hold'],
  hold: ['zero order hold'],
  sample: ['zero order hold'],
  time: ['clock'],
  constant: ['constant'],
  wave: ['sine'],
  oscillator: ['sine'],
  integrate: ['integrator'],
  random: ['random walk'],
  wander: ['random walk'],
  state: ['supervisor', 'agent modes'],
  'state machine': ['supervisor', 'agent modes'],
  switch: ['supervisor', 'agent modes'],
  mode: ['supervisor', 'agent modes'],
  learn: ['policy', 'action', 'task'],
  rl: ['policy', 'action', 'task'],
  split: ['demux', 'select'],
  combine: ['mux', 'concatenate'],
  merge: ['mux', 'concatenate'],
  pick: ['select', 'gather'],
  cover: ['coverage'],
  explore: ['coverage', 'random walk'],
  physics: ['physics world', 'mujoco'],
};

const STOP = new Set(['a', 'an', 'the', 'to', 'of', 'and', 'or', 'for', 'in', 'on', 'with', 'by', 'at']);

/** Lower-case words of a name: "PointToPoint" -> "point to point". */
export function nameWords(name: string): string {
  return name
    .replace(/([a-z0-9])([A-Z])/g, '$1 $2')
    .replace(/([A-Z])([A-Z][a-z])/g, '$1 $2')
    .toLowerCase();
}

function norm(s: string): string {
  return s
    .toLowerCase()
    .replace(/[^a-z0-9 ]+/g, ' ')
    .replace(/\s+/g, ' ')
    .trim();
}

/** Whether `text` has `w` at the start of one of its words (" waypoints" has "waypoint"). */
function hasWord(text: string, w: string): boolean {
  return ` ${text}`.includes(` ${w}`);
}

function synonymsOf(term: string): string[] {
  if (SYNONYMS[term]) return SYNONYMS[term];
  // a plural or a verb form: "goals", "avoiding"
  for (const k of [term.replace(/e?s$/, ''), term.replace(/ing$/, ''), term.replace(/ing$/, 'e')]) if (k !== term && SYNONYMS[k]) return SYNONYMS[k];
  return [];
}

/** The query's terms: phrases that have synonyms kept whole ("go to"), stop words dropped. */
export function terms(query: string): string[] {
  let q = norm(query);
  const out: string[] = [];
  for (const phrase of Object.keys(SYNONYMS).filter((k) => k.includes(' '))) {
    if (` ${q} `.includes(` ${phrase} `)) {
      out.push(phrase);
      q = ` ${q} `.replace(` ${phrase} `, ' ').trim();
    }
  }
  const words = q.split(' ').filter(Boolean);
  const content = words.filter((w) => !STOP.has(w));
  return [...out, ...(content.length || out.length ? content : words)];
}

/** How well a block matches a query: 0 for no match; a name match ranks above a summary
 * match, which ranks above a match through synonyms. */
export function score(b: BlockDecl, query: string): number {
  const q = norm(query);
  if (!q) return 1;
  const raw = b.name.toLowerCase();
  const words = nameWords(b.name);
  const type = b.type.toLowerCase();
  const summary = norm(b.summary ?? '');
  const flat = q.replace(/ /g, '');
  let s = 0;
  if (raw === flat) s += 10_000;
  else if (raw.startsWith(flat)) s += 5_000;
  else if (raw.includes(flat) || type.includes(flat)) s += 3_000;
  let matched = 0;
  const ts = terms(query);
  for (const t of ts) {
    const tf = t.replace(/ /g, '');
    if (raw.includes(tf) || hasWord(words, t)) {
      s += 400;
      matched++;
      continue;
    }
    if (hasWord(summary, t)) {
      s += 100;
      matched++;
      continue;
    }
    const syn = synonymsOf(t);
    const inName = syn.filter((x) => hasWord(words, x) || raw.includes(x.replace(/ /g, ''))).length;
    const inSummary = syn.filter((x) => hasWord(summary, x)).length;
    if (inName || inSummary) {
      s += 20 * Math.min(inName, 3) + 5 * Math.min(inSummary, 3);
      matched++;
    }
  }
  if (matched < ts.length && s < 3_000) return 0;
  return s;
}

/** The blocks matching `query`, best first (ties in palette order). */
export function search(blocks: BlockDecl[], query: string): BlockDecl[] {
  if (!norm(query)) return blocks;
  return blocks
    .map((b, i) => ({ b, i, s: score(b, query) }))
    .filter((x) => x.s > 0)
    .sort((a, b) => b.s - a.s || a.i - b.i)
    .map((x) => x.b);
}
