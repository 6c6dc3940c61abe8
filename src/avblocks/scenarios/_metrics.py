"""The numbers and the plot a scenario file's ``outcome:`` and ``figures:``
sections can name (:mod:`avblocks.scenarios.report` runs them): first
times, closest approaches, final means, fractions of agents over time."""

from __future__ import annotations

import numpy as np


# ------------------------------------------------------------------ numbers
def first_time_all(t, flags):
    """First time at which every agent's flag (T, N) is true, or None."""
    flags = np.asarray(flags).reshape(len(t), -1).astype(bool)
    allk = flags.all(axis=1)
    return float(t[int(np.argmax(allk))]) if allk.any() else None


def min_pairwise_distance(positions, dims=2):
    """Smallest distance between two agents over the run, in their first
    ``dims`` coordinates, and its time index: ``(d, k)``. Uses a k-d tree
    per sample (memory linear in the agents). A sample with a position
    that is not finite gives ``(nan, k)`` at the first such sample."""
    from scipy.spatial import cKDTree
    p = np.asarray(positions, float)[..., :dims]
    best, kbest = np.inf, 0
    for k in range(p.shape[0]):
        if p.shape[1] < 2:
            break
        if not np.isfinite(p[k]).all():
            return float("nan"), k
        dist, _ = cKDTree(p[k]).query(p[k], k=2)
        m = float(dist[:, 1].min())
        if m < best:
            best, kbest = m, k
    return best, kbest


def fmt(x, unit="s"):
    return f"{x:.3g} {unit}".strip() if x is not None else "never"


def all_true(res, signal, what=None):
    a = np.asarray(res[signal]).reshape(len(res.t), -1).astype(bool)
    n = a.shape[1]
    what = what or f"{signal.rsplit('.', 1)[-1]}"
    t_all = first_time_all(res.t, a)
    key = signal.replace(".", "_")
    if t_all is not None:
        return f"all {n} {what} at {t_all:.3g} s", {f"{key}_all_at_s": t_all,
                                                    f"{key}_count": n}
    c = int(a[-1].sum())
    return (f"{c} of {n} {what} by t = {res.t[-1]:.3g} s",
            {f"{key}_all_at_s": None, f"{key}_count": c})


def min_distance(res, signal, label="closest approach"):
    d, k = min_pairwise_distance(res[signal])
    return (f"{label} {d:.3g} m (t = {res.t[k]:.3g} s)",
            {"closest_approach_m": d, "closest_approach_t_s": float(res.t[k])})


def final_mean(res, signal, label=None, unit="", component=None):
    a = np.asarray(res[signal], float)[-1]
    if component is not None:
        a = a[..., int(component)]
    v = float(np.mean(a))
    label = label or f"final mean {signal}"
    return f"{label} {v:.3g}{' ' + unit if unit else ''}", {
        signal.replace(".", "_") + "_final_mean": v}


#: Built-in outcome metrics for scenario files: ``{metric: name, ...args}``.
METRICS = {"all_true": all_true, "min_distance": min_distance,
           "final_mean": final_mean}


# -------------------------------------------------------------------- plots
def plot_fraction(res, signal, ax=None, *, label=None, title=None):
    """Fraction (and count) of agents whose bool signal is true over time,
    with the time everyone is marked; returns the Figure."""
    import matplotlib.pyplot as plt
    a = np.asarray(res[signal]).reshape(len(res.t), -1).astype(bool)
    n = a.shape[1]
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.0, 3.6))
    count = a.sum(axis=1)
    label = label or signal.rsplit(".", 1)[-1]
    ax.plot(res.t, count, color="tab:red", lw=1.5)
    ax.axhline(n, color="0.5", ls="--", lw=1)
    t_all = first_time_all(res.t, a)
    if t_all is not None:
        ax.axvline(t_all, color="0.3", ls=":", lw=1.2)
        right = t_all > res.t[0] + 0.6 * (res.t[-1] - res.t[0])
        ax.annotate(f"all {n} {label}\nat t = {t_all:.3g} s", (t_all, 0.05 * n),
                    xytext=(-4 if right else 4, 0), textcoords="offset points",
                    fontsize=8, ha="right" if right else "left")
    ax.set_xlabel("t [s]")
    ax.set_ylabel(f"{label} agents")
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"{label} agents over time")
    return ax.figure
