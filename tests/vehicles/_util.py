"""Shared helpers for the vehicle tests."""

from __future__ import annotations

import numpy as np

import avblocks as av


def run_const(block, port, value, t_final, dt=0.01, solver="rk4", log=("pose",)):
    """Simulate ``block`` with its input ``port`` held at ``value``.

    Returns (t, {output name: (T, N, ...) array}).
    """
    d = av.Diagram()
    v = d.add(block, name="v")
    c = d.add(av.blocks.Constant(np.asarray(value, dtype=float)), name="c")
    d.connect(c.y, v.port(port))
    refs = [v.port(o) for o in log]
    res = av.simulate(d, t_final, dt=dt, solver=solver, log=refs, progress=False)
    return np.asarray(res.t), {o: np.asarray(res[r]) for o, r in zip(log, refs)}


def wrap(a):
    """Independent angle wrap to (-pi, pi]."""
    a = np.arctan2(np.sin(a), np.cos(a))
    return np.where(a <= -np.pi, a + 2 * np.pi, a)


def angdiff(a, b):
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))
