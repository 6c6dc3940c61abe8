"""K copies of a NumPy :class:`~avblocks.rl.functional.FunctionalEnv` stepped as one call.

The compiled engine batches copies with ``jax.vmap``. The NumPy engine has
no ``vmap``: here the copies' states, outputs and parameters are stacked
with a leading axis ``K`` and one control step runs the engine's major step
once for all of them (:class:`BatchedEngine`: the same output sweeps,
updates and solver arithmetic as :class:`~avblocks.core.engine.Engine`, on
``(K, ...)`` arrays).

Contract (what is batched and what is not)
------------------------------------------
A block is called **once** for the K copies when

- it declares ``batch_axes = True``: its ``output``/``update``/``derivative``
  accept inputs and states with extra leading axes (written with ``...``
  and negative axes, e.g. ``p[..., :, None, :]``) and return arrays with
  those axes (or arrays that broadcast to them); or it is one of the
  library blocks checked to do so (:data:`BATCH_SAFE`);
- and its numeric parameters have the same value in every copy (they are
  bound once, unbatched).

Any other block (a shapely range sensor, a block with a per-copy parameter
such as an episode's drawn goals, a user block without the flag) is called
once per copy inside the same step, on its slice of the stacked arrays,
with that copy's parameters: the results are exact either way, only the
cost differs. Copies whose step counters differ (after a termination) are
stepped in groups of equal counters, so the periodic blocks' sample hits
are those of each copy. Observations, rewards and flags named by port are
read from the stacked outputs; ``observe``/``reward``/``done`` given as
functions are called per copy. Resets draw each copy's episode in turn
(only the copies that end, during a step).

The result equals K independent :meth:`FunctionalEnv.step` calls to
rounding (tests: 1e-12).
"""

from __future__ import annotations

import numpy as np

from . import _engine
from .functional import EnvState, Signals, _fold, _mix


def _batch_safe_classes():
    from ..blocks import Action, Constant, Gain
    return (Action, Constant, Gain)


#: Library blocks whose functions broadcast over leading batch axes as
#: written (each checked against a per-copy loop in tests/rl/test_batched.py).
BATCH_SAFE = ("Action", "Constant", "Gain")


def stack_states(states):
    """One :class:`EnvState` with a leading axis from a list of them."""
    def st(vals):
        return np.stack([np.asarray(v) for v in vals])
    s0 = states[0]
    X = [{k: st([s.X[i][k] for s in states]) for k in s0.X[i]} for i in range(len(s0.X))]
    Y = [{k: st([s.Y[i][k] for s in states]) for k in s0.Y[i]} for i in range(len(s0.Y))]
    theta = {k: st([s.theta[k] for s in states]) for k in s0.theta}
    return EnvState(X, Y, theta, st([s.k for s in states]), st([s.steps for s in states]),
                    st([s.key for s in states]))


def take(state, idx):
    """The copies ``idx`` of a stacked state (a stacked state)."""
    def f(a):
        return a[idx]
    return EnvState([{k: f(v) for k, v in x.items()} for x in state.X],
                    [{k: f(v) for k, v in y.items()} for y in state.Y],
                    {k: f(v) for k, v in state.theta.items()},
                    f(state.k), f(state.steps), f(state.key))


def put(state, idx, part):
    """``state`` with the copies ``idx`` replaced by the stacked ``part``."""
    def g(a, b):
        a = np.array(a, copy=True)
        a[idx] = b
        return a
    return EnvState([{k: g(v, part.X[i][k]) for k, v in x.items()}
                     for i, x in enumerate(state.X)],
                    [{k: g(v, part.Y[i][k]) for k, v in y.items()}
                     for i, y in enumerate(state.Y)],
                    {k: g(v, part.theta[k]) for k, v in state.theta.items()},
                    g(state.k, part.k), g(state.steps, part.steps), g(state.key, part.key))


class BatchedEngine(_engine.Engine):
    """:class:`~avblocks.core.engine.Engine` over stacked copies (module doc).

    ``theta``: the copies' parameters ``{"block.param": (K, ...)}``, set
    with :meth:`set_theta` before a step."""

    def __init__(self, compiled, dt):
        super().__init__(compiled, dt, np)
        safe = _batch_safe_classes()
        self.safe = [bool(getattr(b, "batch_axes", False)) or type(b) in safe
                     for b in compiled.blocks]
        self.K = 0
        self._per_block = [dict() for _ in compiled.blocks]
        self._uniform = [True] * len(compiled.blocks)

    def set_theta(self, theta, K):
        self.K = K
        per = [dict() for _ in self.blocks]
        for path, v in theta.items():
            bpath, _, nm = path.rpartition(".")
            per[self.cd.index(bpath)][nm] = np.asarray(v)
        self._per_block = per
        self._uniform = [all(bool(np.all(v == v[:1])) for v in p.values()) for p in per]

    def _bind(self, i, c=None):
        vals = self._per_block[i]
        if not vals:
            return _engine.bound_parameters([])
        pick = (lambda v: v[0]) if c is None else (lambda v: v[c])
        return _engine.bound_parameters([(self.blocks[i], {k: pick(v)
                                                           for k, v in vals.items()})])

    def _apply(self, i, fn, t, x, u, shapes, **kw):
        """``fn(t, x, u, np)`` for every copy: one call when the block is
        batch-safe with uniform parameters, else one per copy."""
        K = self.K
        if self.safe[i] and self._uniform[i]:
            with self._bind(i):
                out = fn(t, x, u, np, **kw)
            if isinstance(out, dict):
                out = {k: np.broadcast_to(np.asarray(v), (K,) + shapes(k))
                       if shapes(k) is not None else v for k, v in out.items()}
            return out
        outs = []
        for c in range(K):
            xc = {k: v[c] for k, v in x.items()}
            uc = {k: v[c] for k, v in u.items()}
            kc = {k: ({kk: vv[c] for kk, vv in v.items()} if isinstance(v, dict) else v)
                  for k, v in kw.items()}
            with self._bind(i, c):
                outs.append(fn(t, xc, uc, np, **kc))
        if not isinstance(outs[0], dict):
            return np.stack([np.asarray(o) for o in outs])
        return {k: np.stack([np.asarray(o[k]) for o in outs]) for k in outs[0]}

    def _out(self, i, t, X, Y):
        b = self.blocks[i]
        u = {inp: Y[s][o] for inp, s, o in self.src_ft[i]}
        y = self._apply(i, b.output, t, X[i], u,
                        lambda k: tuple(b._outputs[k].shape) if k in b._outputs else None)
        if not isinstance(y, dict):
            y = {self.single_out[i]: y}
        return y

    def update(self, t, X, Y, hits):
        X = list(X)
        for i in self.disc:
            h = hits[i] if self.periodic[i] else True
            if h is False:
                continue
            b = self.blocks[i]
            def shp(k, b=b):
                return tuple(b._init[k].shape) if k in b._init else None
            if b.update_uses_outputs:
                new = self._apply(i, b.update, t, X[i], self.gather(i, Y), shp, y=Y[i])
            else:
                new = self._apply(i, b.update, t, X[i], self.gather(i, Y), shp)
            X[i] = {**X[i], **new}
        return X

    def derivs(self, t, X, Y):
        out = []
        for i in self.cont:
            b = self.blocks[i]
            out.append(self._apply(i, b.derivative, t, X[i], self.gather(i, Y),
                                   lambda k, b=b: tuple(b._init[k].shape)))
        return out


class BatchedEnv:
    """K copies of a NumPy :class:`FunctionalEnv` (module docstring):
    ``reset(keys, params) -> (state, obs (K, N, obs_dim))`` and
    ``step(keys, state, actions (K, N, act_dim), params) -> (state, obs,
    reward (K, N), done (K, N), info)`` with :meth:`FunctionalEnv.step`'s
    automatic reset, the state an :class:`EnvState` with a leading axis."""

    def __init__(self, fenv):
        if fenv.backend != "numpy":
            from ..core.errors import ParameterError
            raise ParameterError("BatchedEnv steps the NumPy engine", param="backend",
                                 expected="numpy", found=fenv.backend)
        self.fenv = fenv
        self.eng = BatchedEngine(fenv.cd, fenv.dt)

    def reset(self, keys, params=None):
        pairs = [self.fenv.reset(k, params) for k in keys]
        return stack_states([p[0] for p in pairs]), np.stack([p[1] for p in pairs])

    # ------------------------------------------------------------- pieces
    def _signals(self, Y):
        cd = self.fenv.cd
        return {f"{cd.names[i]}.{o}": v for i, y in enumerate(Y) for o, v in y.items()}

    def _per_copy(self, spec, sig, K, *args):
        out = []
        for c in range(K):
            sc = Signals({k: v[c] for k, v in sig.items()})
            out.append(np.asarray(spec(sc, *[a[c] for a in args], np)))
        return np.stack(out)

    def _value(self, spec, sig, K, *args):
        return self._per_copy(spec, sig, K, *args) if callable(spec) else np.asarray(sig[spec])

    def _observe(self, sig, K):
        fe = self.fenv
        ob = fe.task.observe
        if callable(ob):
            o = self._per_copy(ob, sig, K)
        else:
            o = np.concatenate([np.reshape(sig[p], (K, fe.n, -1)) for p in ob], axis=-1)
        return np.asarray(o, dtype=np.float32)

    def _step_group(self, state, action, params):
        """``step_env`` for copies sharing one step counter (stacked)."""
        fe, eng = self.fenv, self.eng
        K = action.shape[0]
        theta = state.theta
        if params:
            # only the given parameters change: the episodes' drawn values stay
            first = fe._params(params, {kk: vv[0] for kk, vv in theta.items()})
            theta = {kk: (np.broadcast_to(first[kk], vv.shape)
                          if kk in _param_keys(fe, params) else vv)
                     for kk, vv in theta.items()}
        eng.set_theta(theta, K)
        X = list(state.X)
        ai = fe._ai
        X[ai] = {**X[ai], "value": np.asarray(action, dtype=X[ai]["value"].dtype)
                 .reshape(K, fe.n, fe.act_dim)}
        Y, k, dt = state.Y, int(state.k[0]), fe.dt
        solver = fe._solver
        X, Y, k = _engine.advance(eng, solver, fe._after_action, X, Y, k, dt,
                                  fe.task.substeps)
        sig = self._signals(Y)
        obs = self._observe(sig, K)
        act = sig[f"{fe.cd.names[ai]}.action"]
        reward = np.broadcast_to(np.asarray(self._value(fe.task.reward, sig, K, act),
                                            dtype=np.float32), (K, fe.n))
        if fe.task.done is None:
            term = np.zeros((K, fe.n), dtype=bool)
        else:
            term = np.broadcast_to(np.asarray(self._value(fe.task.done, sig, K), bool),
                                   (K, fe.n))
        info = {name: self._value(spec, sig, K) for name, spec in fe.task.info.items()}
        steps = state.steps + 1
        terminated = np.all(term, axis=1)
        truncated = steps >= fe.max_steps
        info["agent_done"] = term
        info["terminated"] = terminated
        info["truncated"] = truncated & ~terminated
        done = np.broadcast_to((terminated | truncated)[:, None], (K, fe.n))
        new = EnvState(X, Y, theta, np.full(K, k, dtype=state.k.dtype), steps, state.key)
        return new, obs, reward, done, info

    def step_env(self, state, action, params=None):
        """One control step of every copy without automatic reset."""
        ks = np.asarray(state.k)
        groups = [np.flatnonzero(ks == v) for v in np.unique(ks)]
        if len(groups) == 1:
            return self._step_group(state, np.asarray(action), params)
        parts = [(g, self._step_group(take(state, g), np.asarray(action)[g], params))
                 for g in groups]
        K = len(ks)
        new = state
        obs = reward = done = None
        info = {}
        for g, (s, o, r, d, inf) in parts:
            new = put(new, g, s)
            if obs is None:
                obs = np.zeros((K,) + o.shape[1:], o.dtype)
                reward = np.zeros((K,) + r.shape[1:], r.dtype)
                done = np.zeros((K,) + d.shape[1:], d.dtype)
                info = {k: np.zeros((K,) + np.shape(v)[1:], np.asarray(v).dtype)
                        for k, v in inf.items()}
            obs[g], reward[g], done[g] = o, r, d
            for k, v in inf.items():
                info[k][g] = v
        return new, obs, reward, done, info

    def step(self, keys, state, action, params=None):
        """One control step with :meth:`FunctionalEnv.step`'s automatic reset
        (per copy: the same keys, so a copy's episodes equal its own env's)."""
        new, obs, reward, done, info = self.step_env(state, action, params)
        info["final_obs"] = obs
        ended = np.flatnonzero(done[:, 0])
        if len(ended):
            fe, rng = self.fenv, _engine.rng
            rs = []
            for c in ended:
                _, k_reset = rng.split(np.asarray(keys[c], dtype=np.uint32), np, 2)
                rkey = _fold(k_reset, 0, np)
                rs.append(fe.reset(_mix(np.asarray(state.key[c]), rkey, np), params))
            new = put(new, ended, stack_states([r[0] for r in rs]))
            obs = np.array(obs, copy=True)
            obs[ended] = np.stack([r[1] for r in rs])
        return new, obs, reward, done, info


def _param_keys(fe, params):
    keys = set()
    for path in (params or {}):
        i, name = fe.cd.param_index(path)
        keys.add(f"{fe.cd.names[i]}.{name}")
    return keys
