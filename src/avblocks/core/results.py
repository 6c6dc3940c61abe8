"""Logged signals of a run: time x agent x component arrays.

>>> import numpy as np, avblocks as av
>>> r = av.Results(np.array([0.0, 1.0]), {"a.y": np.zeros((2, 3, 2))})
>>> r["a.y"].shape
(2, 3, 2)
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .atomic import atomic_write_bytes
from .atomic import os_reason as _os_reason
from .errors import AvError
from .plotting import get_backend
from .ports import Port


class Results:
    """Recorded outputs of a simulation.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Times of the samples.
    data : dict of str -> ndarray, shape (T, *port shape)
        One array per logged port, keyed ``"block.port"``.
    ports : dict of str -> Port
        The specs of the logged ports (units, component labels).
    meta : dict
        Run facts: solver, dt, seed, steps, agents, wall time, real-time
        factor, overruns (when paced), error (when it failed).
    """

    def __init__(self, t, data, ports=None, meta=None, aliases=None, *, runs=None):
        self.t = np.asarray(t)
        self.data = dict(data)
        self.ports = dict(ports or {})
        self.meta = dict(meta or {})
        self.aliases = dict(aliases or {})
        #: number of runs of an ensemble (signals then have a leading run
        #: axis: ``(runs, T, ...)``), ``None`` for a single run.
        self.runs = None if runs is None else int(runs)
        #: ``{"block.state": array}`` at the end of the run, when the backend
        #: returns it (``(runs, ...)`` for an ensemble), else ``None``.
        self.final_state = None
        for k, v in self.data.items():
            nt = len(v) if self.runs is None else (v.shape[1] if v.ndim > 1 else -1)
            if self.runs is not None and len(v) != self.runs:
                raise AvError(f"signal '{k}' has {len(v)} runs but runs={self.runs}")
            if nt != len(self.t):
                raise AvError(f"signal '{k}' has {nt} samples but there are "
                              f"{len(self.t)} times")

    def _key(self, ref) -> str:
        from .diagram import PortRef
        key = ref.path if isinstance(ref, PortRef) else str(ref)
        key = self.aliases.get(key, key)
        if key not in self.data:
            raise KeyError(f"'{key}' was not logged; logged: {sorted(self.data)}")
        return key

    def __getitem__(self, ref) -> np.ndarray:
        return self.data[self._key(ref)]

    def __contains__(self, ref):
        try:
            self._key(ref)
            return True
        except KeyError:
            return False

    def keys(self):
        return self.data.keys()

    def final(self, ref) -> np.ndarray:
        """Last logged value of a signal (of every run for an ensemble)."""
        return self[ref][-1] if self.runs is None else self[ref][:, -1]

    def run(self, r) -> Results:
        """Run ``r`` of an ensemble as single-run Results."""
        if self.runs is None:
            raise AvError("these results hold a single run (no run axis)")
        meta = dict(self.meta)
        if "seeds" in meta:
            meta["seed"] = meta["seeds"][r]
        out = Results(self.t, {k: v[r] for k, v in self.data.items()}, self.ports, meta,
                      self.aliases)
        if self.final_state is not None:
            out.final_state = {k: v[r] for k, v in self.final_state.items()}
        return out

    def __repr__(self):
        lead = 1 if self.runs is None else 2
        sigs = ", ".join(f"{k} {v.shape[lead:]}" for k, v in self.data.items())
        runs = "" if self.runs is None else f"{self.runs} runs x "
        return (f"Results({runs}{len(self.t)} samples, t=[{self.t[0] if len(self.t) else 0}"
                f", {self.t[-1] if len(self.t) else 0}]: {sigs})")

    def _repr_html_(self):
        """A compact table for Jupyter, as an xarray Dataset shows itself:
        the runs, samples and time span, one row per signal (shape per
        sample, dtype, unit, finite range), and what the run reported."""
        import html
        lead = 1 if self.runs is None else 2
        n = len(self.t)
        span = (f"t = {self.t[0]:g} .. {self.t[-1]:g} s" if n else "no samples")
        step = f", every {self.t[1] - self.t[0]:g} s" if n > 1 else ""
        runs = "" if self.runs is None else f"{self.runs} runs &times; "
        rows = []
        for k, v in self.data.items():
            spec = self.ports.get(k)
            unit = getattr(spec, "unit", None) or ""
            rng = ""
            if v.size and np.issubdtype(v.dtype, np.number):
                fin = v[np.isfinite(v)] if np.issubdtype(v.dtype, np.floating) else v
                if fin.size:
                    rng = f"{fin.min():.4g} .. {fin.max():.4g}"
            rows.append("<tr>" + "".join(
                f"<td style='text-align:left'>{html.escape(str(c))}</td>"
                for c in (k, v.shape[lead:], v.dtype, unit, rng)) + "</tr>")
        keep = ("status", "outcome", "wall_time", "realtime_factor", "overruns", "error",
                "interrupted_by", "log_every")
        meta = [f"<b>{html.escape(k)}</b>: {html.escape(_short(self.meta[k]))}"
                for k in keep if k in self.meta]
        head = ("<tr>" + "".join(f"<th style='text-align:left'>{h}</th>" for h in
                                 ("signal", "shape per sample", "dtype", "unit", "range"))
                + "</tr>")
        return (f"<div><b>avblocks.Results</b>: {runs}{n} samples, {span}{step}"
                f"<table>{head}{''.join(rows)}</table>"
                f"{'<div>' + '; '.join(meta) + '</div>' if meta else ''}</div>")

    # ---------------------------------------------------------------- plots
    def plot(self, *signals, ax=None, **options):
        """Quick look, Matplotlib-style: with no ``signals`` the x-y paths
        (:func:`avblocks.viz.plot_trajectories`, into ``ax`` if given), else
        time plots of those signals (:func:`avblocks.viz.plot_signals`).
        Returns the Figure (also pyplot's current figure)."""
        backend = get_backend()
        if not signals:
            return backend.plot_trajectories(self, ax=ax, **options)
        if ax is not None:
            raise AvError("plot(signals...) draws one subplot per component: pass "
                          "fig=... instead of ax=")
        return backend.plot_signals(self, list(signals), **options)

    def animate(self, **options):
        """:func:`avblocks.viz.animate` of these results (shows inline in a
        notebook; ``.save("run.gif")``)."""
        return get_backend().animate(self, **options)

    def to_mcap(self, path, **options):
        """Write the run as an MCAP file for Foxglove (and any MCAP reader):
        each agent's pose as a frame transform and a 3-D body, the logged
        signals as plottable messages, the outcome as a log line. Options
        and format: :func:`avblocks.foxglove.write_results` (the
        ``foxglove`` extra). Returns the path."""
        from .writers import get_writer
        return get_writer("mcap").write_results(self, path, **options)

    # --------------------------------------------------------------- xarray
    def to_xarray(self):
        """The results as an :class:`xarray.Dataset`.

        Each signal is a variable with dimensions ``time``, then ``agent``
        for per-agent signals (``<signal>.agent`` when the agent counts of
        the logged signals differ), then ``<signal>.comp...`` with component
        labels as coordinates when the port declares them. An ensemble's
        results (``runs`` set) put a ``run`` dimension first, with the runs'
        seeds as a ``seed`` coordinate.
        """
        import xarray as xr

        counts = {p.n for k, p in self.ports.items() if p.n is not None}
        shared_agent = len(counts) == 1
        variables, coords = {}, {"time": ("time", self.t)}
        lead = ["time"] if self.runs is None else ["run", "time"]
        if self.runs is not None:
            coords["run"] = ("run", np.arange(self.runs))
            if len(self.meta.get("seeds") or ()) == self.runs:
                coords["seed"] = ("run", np.asarray(self.meta["seeds"]))
        for k, v in self.data.items():
            p = self.ports.get(k, Port(k.replace(".", "_"), v.shape[len(lead):],
                                       v.dtype.name))
            dims = list(lead)
            rest = list(v.shape[len(lead):])
            if p.agents and rest:
                dims.append("agent" if shared_agent else f"{k}.agent")
                rest = rest[1:]
            for j, _ in enumerate(rest):
                dims.append(f"{k}.comp" if j == 0 else f"{k}.comp{j}")
            if p.labels and rest and len(p.labels) == rest[-1]:
                coords[dims[-1]] = (dims[-1], list(p.labels))
            variables[k] = (dims, v, {"unit": p.unit, "doc": p.doc,
                                      "agents": int(p.agents)})
        ds = xr.Dataset(variables, coords=coords)
        ds.attrs["avblocks_meta"] = json.dumps(self.meta, default=_jsonable)
        if self.aliases:
            # the names the user logged by ("fleet.position" for a subsystem's
            # "fleet.quad.position"), kept across save/load
            ds.attrs["avblocks_aliases"] = json.dumps(self.aliases)
        return ds

    def save(self, path) -> Path:
        """Save to NetCDF (``.nc``, through h5netcdf) or Zarr (``.zarr``).

        The file is written under a temporary name next to ``path`` and
        renamed into place only once complete, so an existing file is never
        left half-overwritten and a full disk leaves no corrupt file; every
        failure is an :class:`AvError` naming the file and the cause."""
        path = Path(path)
        if path.suffix not in (".nc", ".zarr"):
            raise AvError(f"cannot save results to '{path}': unknown format",
                          expected="a .nc (NetCDF) or .zarr path", found=path.suffix or "no suffix")
        if not path.parent.is_dir():
            raise AvError(f"cannot save results to '{path}': no folder '{path.parent}'",
                          hint="create the folder first")
        try:
            ds = self.to_xarray()
        except ImportError as e:
            raise AvError(f"saving results needs xarray: {e}",
                          hint="pip install avblocks") from None
        if path.suffix == ".zarr":
            return _save_zarr(ds, path)
        try:
            # encode in memory: a write error then never leaves HDF5 with a
            # half-written file open (which can crash the interpreter)
            blob = ds.to_netcdf(engine="h5netcdf")
        except ImportError as e:
            raise AvError(f"saving NetCDF needs h5netcdf: {e}",
                          hint="pip install h5netcdf") from None
        atomic_write_bytes(path, bytes(blob))
        return path

    @classmethod
    def load(cls, path) -> Results:
        """Load results saved by :meth:`save`; any problem (missing, not a
        results file, truncated, a missing reader) is an :class:`AvError`.

        A results file may come from someone else: what it declares is
        checked before anything is decoded (:mod:`avblocks.core.stored`):
        its arrays' sizes within ``AVBLOCKS_MAX_MEMORY``, plain codecs,
        chunks that inflate to no more than their size, and for NetCDF no
        HDF5 link, external or virtual storage (data from other files)."""
        path = Path(path)
        if not path.exists():
            raise AvError(f"no results file at {path}")
        if not path.is_dir() and not path.is_file():
            raise AvError(f"'{path}' is not a regular file (a FIFO, a socket or a device)")
        try:
            import xarray as xr

            from .stored import check_hdf5, check_zarr_group
            # what the file declares is checked before anything is decoded
            # (sizes, codecs, compression bombs, HDF5 links and external data)
            if path.suffix == ".zarr":
                import zarr
                check_zarr_group(zarr.open_group(str(path), mode="r"), str(path))
                ds = xr.open_zarr(path).load()
            else:
                check_hdf5(path)
                with xr.open_dataset(path, engine="h5netcdf") as f:
                    ds = f.load()
            return cls.from_xarray(ds)
        except AvError:
            raise
        except ImportError as e:
            raise AvError(f"cannot read '{path}': a reader is missing ({e})",
                          hint="pip install 'avblocks[all]'") from None
        except MemoryError:
            raise AvError(f"cannot read '{path}': it does not fit in memory") from None
        except Exception as e:  # noqa: BLE001 - h5py/xarray/json/zarr errors
            raise AvError(f"cannot read '{path}' as avblocks results: "
                          f"{type(e).__name__}: {e}",
                          hint="the file may be truncated or not made by Results.save") from None

    @classmethod
    def from_xarray(cls, ds) -> Results:
        data, ports = {}, {}
        runs = ds.sizes["run"] if "run" in ds.dims else None
        for k, var in ds.data_vars.items():
            v = np.asarray(var.values)
            data[k] = v
            lead = 1 if runs is None else 2
            labels = ()
            last = var.dims[-1]
            if last in ds.coords and last != "time" and not last.endswith("agent"):
                labels = tuple(str(s) for s in ds.coords[last].values)
            ports[k] = Port(k.rsplit(".", 1)[-1], v.shape[lead:], v.dtype.name,
                            str(var.attrs.get("unit", "")), labels,
                            str(var.attrs.get("doc", "")),
                            bool(var.attrs.get("agents", 1)))
        meta = json.loads(ds.attrs.get("avblocks_meta", "{}"))
        aliases = json.loads(ds.attrs.get("avblocks_aliases", "{}"))
        if not isinstance(aliases, dict):
            aliases = {}
        aliases = {str(k): str(v) for k, v in aliases.items() if str(v) in data}
        return cls(np.asarray(ds["time"].values), data, ports, meta, aliases, runs=runs)


def _save_zarr(ds, path):
    import shutil
    import tempfile
    tmp = None
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part",
                                    dir=path.parent))
        ds.to_zarr(tmp / "store.zarr", mode="w")
        old = None
        if path.exists():
            old = path.with_name(f".{path.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            path.rename(old)
        (tmp / "store.zarr").rename(path)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except ImportError as e:
        raise AvError(f"saving Zarr needs the zarr package: {e}",
                      hint="pip install zarr (or save to .nc)") from None
    except OSError as e:
        raise AvError(f"could not write '{path}': {_os_reason(e)}") from None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return path


def _jsonable(o):
    if isinstance(o, np.generic):
        return o.item()
    return str(o)


def _short(v, limit=120):
    """A value as at most ``limit`` characters of text."""
    text = f"{v:.4g}" if isinstance(v, float) else str(v)
    return text if len(text) <= limit else text[: limit - 3] + "..."
