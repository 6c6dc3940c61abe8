"""A finished (or partly finished) sweep, read back from its store."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import store
from .spec import Spec, SweepError

STATUS_MISSING, STATUS_DONE, STATUS_FAILED = "missing", "done", "failed"


def _coord(values):
    """Grid values as a coordinate: numbers stay numbers, anything else text
    (variable-length strings, see :func:`_text_array`)."""
    if all(isinstance(v, bool | int | float) and not isinstance(v, bool) for v in values):
        return np.asarray(values)
    return _text_array([str(v) for v in values])


def _text_array(values):
    """Texts as an object array of ``str``: written to Zarr as variable-length
    strings, so a dataset written again (a resume) never meets a fixed width
    it does not fit (``<U4`` 'done' against ``<U6`` 'failed')."""
    out = np.empty(len(values), dtype=object)
    out[:] = [str(v) for v in values]
    return out


def _budget(need, what, spec):
    """Refuse a dataset whose arrays would pass the memory limit before they
    are allocated: a store's definition declares the cases (up to 10^7) and
    one case's metric its shape (up to 10^4 values), so a 50 kB store could
    ask for hundreds of GB."""
    from ..core.memlimit import describe, too_large
    if too_large(need):
        raise SweepError(f"the sweep's dataset would take {describe(need)} at {what} "
                         f"({spec.n_cases:,} cases)",
                         hint="read cases one by one (study.metrics(case), "
                              "study.results(case)), or set AVBLOCKS_MAX_MEMORY")


class Study:
    """The results of a sweep stored at ``out``.

    Attributes
    ----------
    out : str
        The store.
    spec : Spec
        Scenario, grid, seeds, metrics.
    last_run : dict
        Counts of the call that produced this object (``ran``, ``done``,
        ``failed``, ``wall_s``); empty when opened with :meth:`open`.
    """

    def __init__(self, out, last_run=None):
        self.out = str(out)
        root = store.open_store(out)
        data, _pickle = store.read_spec(root)        # checked entry by entry
        self.spec = Spec(data)
        self._root = root
        self.last_run = dict(last_run or {})

    @classmethod
    def open(cls, out) -> Study:
        """Open a sweep's store (finished or not)."""
        return cls(out)

    # ------------------------------------------------------------ index
    def records(self) -> dict:
        """``{case_id: record}`` of every finished case (done or failed)."""
        return store.scan_cases(self._root, self.spec.n_cases)

    def status(self) -> np.ndarray:
        """Status of each case, shaped like the grid + seed."""
        st = np.full(self.spec.n_cases, STATUS_MISSING, dtype=object)
        for cid, rec in self.records().items():
            if cid < self.spec.n_cases:
                st[cid] = rec["status"]
        return st.reshape(self.spec.shape)

    def counts(self) -> dict:
        st = self.status().ravel()
        return {s: int((st == s).sum()) for s in (STATUS_DONE, STATUS_FAILED,
                                                  STATUS_MISSING)}

    def missing(self, retry_failed=False) -> list:
        st = self.status().ravel()
        bad = (st == STATUS_MISSING) | ((st == STATUS_FAILED) if retry_failed else False)
        return [int(i) for i in np.flatnonzero(bad)]

    def errors(self) -> dict:
        """``{case label: error text}`` of the failed cases."""
        return {self.spec.label(cid): rec.get("error", "")
                for cid, rec in sorted(self.records().items())
                if rec["status"] == STATUS_FAILED}

    def metrics(self, case_id) -> dict:
        """The stored metrics of one case."""
        return store.read_metrics(self._root, case_id)

    def results(self, case_id):
        """The stored (decimated) logs of one case as :class:`avblocks.Results`."""
        from ..core.results import Results
        logs = store.read_logs(self._root, case_id)
        if not logs:
            raise SweepError(f"case {case_id} has no stored logs",
                             hint="run the sweep with log=[ports] (CLI: --log PORT)")
        t = logs.pop("time")
        return Results(t, logs, meta={"case": self.spec.label(case_id)})

    # ------------------------------------------------------------ xarray
    def to_xarray(self, logs=False):
        """An :class:`xarray.Dataset` with dims ``(grid names..., seed)``.

        One variable per metric (NaN where a case failed or is missing;
        extra dims ``<metric>_dim0...`` for array metrics), ``status``,
        ``error`` and ``wall_s``. ``logs=True`` adds the stored logs as
        ``log.<port>`` with dims ``(..., seed, time, <port>_dim0...)``
        (they are read into memory: pick a sub-grid with ``.sel`` for
        large sweeps, or use :meth:`results` per case).
        """
        import xarray as xr
        sp = self.spec
        recs = self.records()
        dims = sp.dims
        coords = {k: _coord(v) for k, v in sp.grid.items()}
        coords["seed"] = np.asarray(sp.seeds)
        status = np.full(sp.n_cases, STATUS_MISSING, dtype=object)
        error = np.full(sp.n_cases, "", dtype=object)
        wall = np.full(sp.n_cases, np.nan)
        vals: dict = {}
        for cid, rec in recs.items():
            status[cid] = rec["status"]
            error[cid] = rec.get("error", "")
            wall[cid] = rec.get("wall_s", np.nan) if rec.get("wall_s") is not None else np.nan
            if rec["status"] == STATUS_DONE:
                for name, v in store.read_metrics(self._root, cid).items():
                    vals.setdefault(name, {})[cid] = v
        variables = {"status": (dims, _text_array(status).reshape(sp.shape)),
                     "error": (dims, _text_array(error).reshape(sp.shape)),
                     "wall_s": (dims, wall.reshape(sp.shape), {"unit": "s"})}
        need = 3 * 8 * sp.n_cases               # status, error, wall_s
        for name in sp.data["metrics"]:
            per = vals.get(name, {})
            shape = next(iter(per.values())).shape if per else ()
            need += 8 * sp.n_cases * int(np.prod(shape))
            _budget(need, f"metric '{name}'", sp)
            arr = np.full((sp.n_cases,) + shape, np.nan)
            for cid, v in per.items():
                if v.shape != shape:
                    raise SweepError(f"metric '{name}' has shape {v.shape} in case "
                                     f"{sp.label(cid)} but {shape} elsewhere")
                arr[cid] = v
            mdims = dims + [f"{name}_dim{i}" for i in range(len(shape))]
            variables[name] = (mdims, arr.reshape(sp.shape + shape))
        if logs:
            variables.update(self._logs_variables(recs, need))
        ds = xr.Dataset(variables, coords=coords)
        ds.attrs.update({"scenario": sp.data["scenario"]["name"],
                         "store": self.out, "metrics": list(sp.data["metrics"])})
        return ds

    def write_dataset(self):
        """Write :meth:`to_xarray` (with the logs, when the sweep stored
        them) at the store's root, so that plain ``xarray.open_zarr(store)``
        opens the whole sweep: grid names and ``seed`` as dimensions with
        their values as coordinates, one variable per metric, ``status``,
        ``error``, ``wall_s``. The per-case groups under ``cases/`` stay
        (they are what a crash leaves complete). Called when a sweep or a
        resume finishes; missing cases are NaN and ``status`` says so."""
        ds = self.to_xarray(logs=bool(self.spec.data.get("log")) and self._has_logs())
        ds.attrs["store"] = "."                 # the dataset is the store itself
        root = store.open_group(self.out, mode="r+")
        keep = dict(root.attrs)                 # xarray replaces the group's attributes
        # the dataset is derived from the cases: the one written before (by a
        # run, a resume, or an older avblocks with fixed-width texts) goes
        # first, so a new one never has to match its data types or shapes
        for name in list(root.array_keys()):
            del root[name]
        ds.to_zarr(self.out, mode="a", consolidated=False, zarr_format=3)
        root = store.open_group(self.out, mode="r+")
        root.attrs.update(keep)
        self._root = store.open_store(self.out)
        return self.out

    def _has_logs(self):
        done = [c for c, r in self.records().items() if r["status"] == STATUS_DONE]
        return bool(done) and bool(store.read_logs(self._root, done[0]))

    def _logs_variables(self, recs, need=0):
        sp = self.spec
        done = [cid for cid, r in recs.items() if r["status"] == STATUS_DONE]
        if not done:
            return {}
        first = store.read_logs(self._root, done[0])
        if not first:
            raise SweepError("this sweep stored no logs",
                             hint="run it with log=[ports] (CLI: --log PORT)")
        out = {}
        for name, v0 in first.items():
            need += 8 * sp.n_cases * int(np.prod(v0.shape))
            _budget(need, f"log '{name}'", sp)
            arr = np.full((sp.n_cases,) + v0.shape, np.nan)
            for cid in done:
                v = store.read_logs(self._root, cid)[name]
                if v.shape != v0.shape:
                    raise SweepError(f"log '{name}' has shape {v.shape} in case "
                                     f"{sp.label(cid)} but {v0.shape} in others",
                                     hint="read cases one by one with study.results(case)")
                arr[cid] = v
            extra = ["time"] if name == "time" else ["time"] + [
                f"{name}_dim{i}" for i in range(v0.ndim - 1)]
            key = "log_time" if name == "time" else f"log.{name}"
            out[key] = (sp.dims + extra[:v0.ndim], arr.reshape(sp.shape + v0.shape))
        return out

    # ----------------------------------------------------------- reports
    def summary(self, max_rows=40) -> str:
        """A text table: one row per grid point, mean +- std over seeds of
        each scalar metric, and the counts of done/failed cases."""
        ds = self.to_xarray()
        sp = self.spec
        names = [m for m in sp.data["metrics"] if ds[m].ndim == len(sp.dims)]
        gdims = list(sp.grid)
        head = gdims + ["done", "failed"] + names
        rows = []
        st = ds["status"]
        points = list(np.ndindex(*sp.shape[:-1]))
        for idx in points[:max_rows]:
            sel = dict(zip(gdims, idx))
            row = [str(ds[k].values[i]) for k, i in sel.items()]
            s = st.isel(sel).values
            row += [str(int((s == STATUS_DONE).sum())), str(int((s == STATUS_FAILED).sum()))]
            for m in names:
                v = ds[m].isel(sel).values.astype(float)
                v = v[np.isfinite(v)]
                row.append(f"{v.mean():.4g} +- {v.std():.2g}" if len(v) else "-")
            rows.append(row)
        widths = [max(len(h), *(len(r[j]) for r in rows)) if rows else len(h)
                  for j, h in enumerate(head)]
        lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths)),
                 "  ".join("-" * w for w in widths)]
        lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
        if len(points) > max_rows:
            lines.append(f"... {len(points) - max_rows} more grid points")
        c = self.counts()
        lines.append(f"{sp.n_cases} cases: {c['done']} done, {c['failed']} failed, "
                     f"{c['missing']} missing  ({self.out})")
        return "\n".join(lines)

    def plot(self, folder=None) -> list:
        """One PNG per scalar metric next to the store (``<stem>_<metric>.png``):
        a heatmap of the mean over seeds for two grid dims (spread in each
        cell), lines with mean and +-1 std band otherwise."""
        from .plot import plot_study
        return plot_study(self, folder)

    def __repr__(self):
        c = self.counts()
        return (f"Study('{self.out}': {self.spec.data['scenario']['name']}, grid "
                f"{dict(zip(self.spec.dims, self.spec.shape))}, {c['done']} done, "
                f"{c['failed']} failed, {c['missing']} missing)")


def default_plot_dir(out) -> Path:
    p = Path(str(out))
    return p.parent if str(p.parent) else Path(".")
