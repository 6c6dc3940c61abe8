// Shapes shared by the front end and the Python side (see ../API.md).

export type Json = null | boolean | number | string | Json[] | { [k: string]: Json };

export type Wire = [string, string];
export type XY = [number, number];

export interface Group {
  blocks: string[];
  groups?: string[];
  position?: XY;
  label?: string;
}

export interface EditorState {
  layout?: Record<string, XY>;
  groups?: Record<string, Group>;
  viewport?: [number, number, number];
}

export interface Block {
  type: string;
  [param: string]: Json;
}

export interface Doc {
  name?: string;
  description?: string;
  parameters?: Record<string, Json>;
  blocks: Record<string, Block>;
  wires: Wire[];
  simulation?: Record<string, Json>;
  editor?: EditorState;
  [key: string]: unknown;
}

export interface PortDecl {
  name: string;
  shape?: string;
  dtype?: string;
  unit?: string | null;
  doc?: string;
}

export interface ParamDecl {
  name: string;
  kind: string;
  shape?: string | null;
  default?: Json;
  required?: boolean;
  bounds?: [number | null, number | null] | null;
  unit?: string | null;
  doc?: string;
  choices?: Json[] | null;
  numeric?: boolean;
}

export interface BlockDecl {
  type: string;
  name: string;
  summary?: string;
  doc?: string;
  inputs: PortDecl[];
  outputs: PortDecl[];
  params: ParamDecl[];
  template?: Record<string, Json>;
  ports_depend_on?: string[];
}

export interface Family {
  name: string;
  title: string;
  blocks: BlockDecl[];
}

export interface GeneratorDecl {
  name: string;
  doc?: string;
  args: { name: string; kind?: string; required?: boolean; default?: Json; doc?: string }[];
  returns?: string;
}

export interface Palette {
  families: Family[];
  generators: GeneratorDecl[];
  version?: string;
  parameters?: Record<string, Json>;
}

export interface ValidationError {
  message: string;
  kind?: string;
  block?: string | null;
  port?: string | null;
  param?: string | null;
  wire?: Wire | null;
  cycle?: string[] | null;
  /** The document entry it is about: "blocks.drive.gain", "simulation.t_final", "parameters.agents". */
  field?: string | null;
  /** The diagram parameters it is also about (the failing value refers to them). */
  refs?: string[];
}

export interface Signal {
  shape: string;
  dtype?: string;
}

export interface Validation {
  ok: boolean;
  errors: ValidationError[];
  signals: Record<string, Signal>;
  /** Optional: the ports each block instance has once built (blocks whose ports depend on parameters). */
  ports?: Record<string, { inputs: string[]; outputs: string[] }>;
  elapsed_ms?: number;
}

export interface FileList {
  root: string;
  files: { path: string; name: string }[];
  builtins: { name: string; kind?: string; editable?: boolean }[];
  /** What the page opens first (`avblocks edit NAME|FILE`), or null for an empty diagram. */
  initial?: { path?: string; builtin?: string } | null;
}

export interface Loaded {
  document: Doc;
  path: string | null;
  builtin: string | null;
  revision: string | null;
}

export interface RunStatus {
  run?: string;
  status: 'running' | 'done' | 'failed' | 'cancelled';
  progress: number;
  t?: number;
  t_final?: number;
  outcome?: string | null;
  numbers?: Record<string, Json>;
  figures?: { name: string; url: string }[];
  signals?: string[];
  error?: { message: string; kind?: string } | string | null;
}

export interface SignalData {
  t: number[];
  values: (number | number[] | number[][])[];
  shape?: string | number[];
  labels?: string[];
}
