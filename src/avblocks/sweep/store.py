"""The Zarr layout of a sweep (zarr v3, a directory or any URL zarr opens).

::

    sweep.zarr/                    attrs: avblocks_sweep (the spec, JSON),
                                          (no code: custom metrics by reference)
      cases/
        c0000017/                  one group per case, written by the worker
                                   that ran it; attrs (written last):
                                   status "done" | "failed", error, wall_s,
                                   seed, values, worker, finished
          metrics/<name>           the metric's value (0-d or small array)
          logs/time, logs/<port>   optional decimated logs

A case group without a ``status`` attribute (a worker died while writing it)
counts as missing and is run again by ``resume``. Workers never write the
same group at the same time and never touch the root's attributes, so no
locking is needed; the client writes only the root attributes and the
records of cases whose worker died too often (Dask's ``KilledWorker``).
"""

from __future__ import annotations

import json
import os
import socket
import time
import traceback

import numpy as np

from .spec import SweepError


def case_name(case_id: int) -> str:
    return f"c{int(case_id):07d}"


def _zarr():
    try:
        import zarr
    except ImportError as e:  # pragma: no cover - the extra is missing
        raise SweepError("sweeps need zarr: pip install 'avblocks[sweep]'") from e
    return zarr


def create_store(out, spec_data: dict, overwrite=False):
    """A new store holding the sweep's definition (plain JSON: no code)."""
    zarr = _zarr()
    root = zarr.open_group(str(out), mode="w" if overwrite else "w-")
    root.attrs.update({"avblocks_sweep": json.dumps(spec_data)})
    root.create_group("cases")
    return root


def open_group(out, mode="r"):
    """The store's root group as it is (no check that it is a sweep)."""
    return _zarr().open_group(str(out), mode=mode)


def open_store(out, mode="r"):
    zarr = _zarr()
    try:
        root = zarr.open_group(str(out), mode=mode)
    except (FileNotFoundError, zarr.errors.GroupNotFoundError) as e:
        raise SweepError(f"no sweep store at '{out}'",
                         hint="run av.sweep(...) or `avblocks sweep` first") from e
    if "avblocks_sweep" not in root.attrs:
        raise SweepError(f"'{out}' is a Zarr store but not an avblocks sweep "
                         "(no 'avblocks_sweep' attribute)")
    return root


def store_exists(out) -> bool:
    zarr = _zarr()
    try:
        zarr.open_group(str(out), mode="r")
        return True
    except (FileNotFoundError, zarr.errors.GroupNotFoundError):
        return False


def read_spec(root) -> tuple[dict, bool]:
    """The stored definition, and whether the store also carries pickled
    code (stores of avblocks 0.1.0): that is never loaded."""
    try:
        data = json.loads(root.attrs["avblocks_sweep"])
    except (TypeError, ValueError) as e:
        raise SweepError("the store's sweep definition is not valid JSON") from e
    if not isinstance(data, dict):
        raise SweepError("the store's sweep definition is not a mapping")
    data = {k: v for k, v in data.items() if not str(k).startswith("_")}
    return data, bool(root.attrs.get("metrics_pickle"))


def write_case(out, case_id, record: dict, metrics=None, logs=None):
    """Write one case's group; the record (with ``status``) goes last."""
    zarr = _zarr()
    cases = zarr.open_group(f"{str(out).rstrip('/')}/cases", mode="r+")
    g = cases.create_group(case_name(case_id), overwrite=True)
    if metrics:
        mg = g.create_group("metrics")
        for name, v in metrics.items():
            mg.create_array(name, data=np.asarray(v), compressors=None)
    if logs:
        lg = g.create_group("logs")
        for name, v in logs.items():
            v = np.ascontiguousarray(v)
            lg.create_array(name, data=v, chunks=v.shape or None)
    rec = dict(record)
    rec.setdefault("worker", f"{socket.gethostname()}:{os.getpid()}")
    rec.setdefault("finished", time.strftime("%Y-%m-%dT%H:%M:%S"))
    g.attrs.update(rec)


def failure_text(exc: BaseException, limit=4000) -> str:
    """``Type: message`` then the innermost frames of the traceback."""
    head = f"{type(exc).__name__}: {exc}"
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__, limit=-4))
    text = head + "\n" + tb
    return text if len(text) <= limit else text[:limit] + "..."


def scan_cases(root) -> dict:
    """``{case_id: attrs}`` of every case group that has a status."""
    out = {}
    if "cases" not in root:
        return out
    for name, g in root["cases"].groups():
        attrs = dict(g.attrs)
        if "status" in attrs and name.startswith("c"):
            out[int(name[1:])] = attrs
    return out


def read_metrics(root, case_id) -> dict:
    g = root["cases"][case_name(case_id)]
    if "metrics" not in g:
        return {}
    return {k: np.asarray(a[...]) for k, a in g["metrics"].arrays()}


def read_logs(root, case_id) -> dict:
    g = root["cases"][case_name(case_id)]
    if "logs" not in g:
        return {}
    return {k: np.asarray(a[...]) for k, a in g["logs"].arrays()}
