"""Pictures of a study: each scalar metric over the grid, mean and spread
over seeds."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _stats(da, seed_dim="seed"):
    v = da.astype(float)
    return v.mean(seed_dim, skipna=True), v.std(seed_dim, skipna=True)


def plot_study(study, folder=None) -> list:
    import warnings

    from matplotlib.figure import Figure  # no pyplot: the user's backend is untouched

    ds = study.to_xarray()
    sp = study.spec
    gdims = list(sp.grid)
    out = Path(str(study.out))
    folder = Path(folder) if folder is not None else out.parent
    folder.mkdir(parents=True, exist_ok=True)
    scen = sp.data["scenario"]["name"]
    files = []
    for m in sp.data["metrics"]:
        da = ds[m]
        if da.ndim != len(sp.dims):       # array metrics: not drawn
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean, std = _stats(da)
        n_ok = np.isfinite(da.astype(float)).sum("seed")
        fig = Figure(figsize=(6.4, 4.8))
        ax = fig.subplots()
        if len(gdims) == 2:
            a, b = gdims
            M = mean.transpose(b, a).values
            im = ax.imshow(M, origin="lower", aspect="auto", cmap="viridis")
            ax.set_xticks(range(len(ds[a])), [f"{v}" for v in ds[a].values])
            ax.set_yticks(range(len(ds[b])), [f"{v}" for v in ds[b].values])
            ax.set_xlabel(a)
            ax.set_ylabel(b)
            S = std.transpose(b, a).values
            N = n_ok.transpose(b, a).values
            finite = M[np.isfinite(M)]
            mid = (finite.min() + finite.max()) / 2 if finite.size else 0
            n_done = (ds["status"] == "done").sum("seed").transpose(b, a).values
            for j in range(M.shape[0]):
                for i in range(M.shape[1]):
                    if np.isfinite(M[j, i]):
                        txt = f"{M[j, i]:.3g}\n±{S[j, i]:.2g}"
                    elif n_done[j, i] == 0:
                        txt = "failed"
                    else:                   # ran, but the metric is NaN (never done)
                        txt = f"NaN\n(0/{len(sp.seeds)})"
                    if np.isfinite(M[j, i]) and N[j, i] < len(sp.seeds):
                        txt += f"\n({N[j, i]}/{len(sp.seeds)})"
                    dark = np.isfinite(M[j, i]) and M[j, i] <= mid
                    ax.text(i, j, txt, ha="center", va="center", fontsize=8,
                            color="white" if dark else "black")
            fig.colorbar(im, ax=ax, label=f"{m} (mean over {len(sp.seeds)} seeds)")
        elif len(gdims) == 0:
            v = da.astype(float).values.ravel()
            ax.hist(v[np.isfinite(v)], bins=min(30, max(5, len(v) // 3)))
            ax.set_xlabel(m)
            ax.set_ylabel("seeds")
        else:
            x = gdims[0]
            xs = ds[x].values
            numeric = np.issubdtype(xs.dtype, np.number)
            xpos = xs if numeric else np.arange(len(xs))
            others = gdims[1:]
            combos = list(np.ndindex(*[len(ds[o]) for o in others])) if others else [()]
            for combo in combos[:10]:
                sel = dict(zip(others, combo))
                mu = mean.isel(sel).transpose(x).values
                sd = std.isel(sel).transpose(x).values
                label = ", ".join(f"{o}={ds[o].values[i]}" for o, i in sel.items()) or m
                line, = ax.plot(xpos, mu, "o-", label=label)
                ax.fill_between(xpos, mu - sd, mu + sd, color=line.get_color(), alpha=0.2)
            if not numeric:
                ax.set_xticks(xpos, [str(v) for v in xs])
            ax.set_xlabel(x)
            ax.set_ylabel(f"{m} (mean ± std over {len(sp.seeds)} seeds)")
            if others or len(combos) > 1:
                ax.legend(fontsize=8)
            ax.grid(alpha=0.3)
        ax.set_title(f"{scen}: {m}")
        fig.tight_layout()
        path = folder / f"{out.stem}_{m}.png"
        fig.savefig(path, dpi=110)
        files.append(path)
    return files
