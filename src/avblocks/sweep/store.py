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

A store may come from someone else (a shared folder, a bucket): it is read
as Zarr v3 only, its definition is checked entry by entry
(:func:`check_definition`: types, sizes, the scenario kinds, at most
:data:`MAX_CASES` cases) before anything uses it, case groups are taken
only by their canonical names, and an array is read only when its data
type is numeric and its codecs are plain compression
(:data:`SAFE_CODECS`), within a size limit. Nothing in a store is
executed or unpickled.
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
import time
import traceback
from pathlib import Path

import numpy as np

from .spec import READABLE_VERSIONS, SCENARIO_KINDS, SPEC_VERSION, SweepError, sha256_of

#: Most cases a stored definition may describe (the grid times the seeds).
MAX_CASES = 10_000_000
#: Largest root ``zarr.json`` read (the definition, with a YAML scenario's text).
MAX_DEFINITION_BYTES = 16 * 1024**2
#: Codecs an array avblocks reads from a store may use (what zarr writes by
#: default for numbers and text); anything else is refused before reading.
SAFE_CODECS = frozenset({"bytes", "transpose", "zstd", "gzip", "blosc", "crc32c",
                         "vlen-utf8"})
#: Largest metadata file of a case group read (its record: status, error
#: text of at most 4,000 characters, seed, worker and its grid values,
#: which the definition, at most as large, holds too).
MAX_CASE_METADATA_BYTES = MAX_DEFINITION_BYTES
#: Most values of one stored metric (what a case may write, see runner).
MAX_METRIC_VALUES = 10_000
_CASE = re.compile(r"^c(\d{7,9})$")
_NAME = re.compile(r"^[^/\x00]{1,200}$")


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
    root = zarr.open_group(str(out), mode="w" if overwrite else "w-", zarr_format=3)
    root.attrs.update({"avblocks_sweep": json.dumps(stored_definition(spec_data))})
    root.create_group("cases")
    return root


def stored_definition(spec_data: dict) -> dict:
    """What a store keeps of a sweep's definition: no key starting with
    ``_`` (this process's functions, a ``.py`` scenario's text), at the top
    or in the scenario."""
    out = {k: v for k, v in spec_data.items() if not str(k).startswith("_")}
    if isinstance(out.get("scenario"), dict):
        out["scenario"] = {k: v for k, v in out["scenario"].items()
                           if not str(k).startswith("_")}
    return out


def open_group(out, mode="r"):
    """The store's root group as it is (no check that it is a sweep)."""
    return _zarr().open_group(str(out), mode=mode, zarr_format=3)


def _definition_size(out):
    """Refuse a local store whose root metadata is too large to read."""
    p = Path(str(out)) / "zarr.json"
    try:
        size = p.stat().st_size if "://" not in str(out) else 0
    except OSError:
        return
    if size > MAX_DEFINITION_BYTES:
        raise SweepError(f"'{out}': the store's root metadata is {size / 1e6:.1f} MB, more "
                         f"than {MAX_DEFINITION_BYTES / 1e6:.0f} MB",
                         hint="a sweep's definition is a few kB (plus a YAML scenario's "
                              "text); this is not a store avblocks wrote")


def open_store(out, mode="r"):
    zarr = _zarr()
    _definition_size(out)
    try:
        root = zarr.open_group(str(out), mode=mode, zarr_format=3)
    except (FileNotFoundError, zarr.errors.GroupNotFoundError) as e:
        raise SweepError(f"no sweep store at '{out}'",
                         hint="run av.sweep(...) or `avblocks sweep` first") from e
    except (ValueError, TypeError, KeyError, OSError) as e:
        raise SweepError(f"'{out}' is not a readable Zarr v3 store: "
                         f"{type(e).__name__}: {str(e)[:200]}") from None
    if "avblocks_sweep" not in root.attrs:
        raise SweepError(f"'{out}' is a Zarr store but not an avblocks sweep "
                         "(no 'avblocks_sweep' attribute)")
    return root


def store_exists(out) -> bool:
    zarr = _zarr()
    try:
        zarr.open_group(str(out), mode="r", zarr_format=3)
        return True
    except (FileNotFoundError, zarr.errors.GroupNotFoundError):
        return False


def read_spec(root) -> tuple[dict, bool]:
    """The stored definition, checked (:func:`check_definition`), and
    whether the store also carries pickled code (stores of avblocks 0.1.0):
    that is never loaded."""
    raw = root.attrs["avblocks_sweep"]
    if not isinstance(raw, str) or len(raw) > MAX_DEFINITION_BYTES:
        raise SweepError("the store's sweep definition is not a JSON text of at most "
                         f"{MAX_DEFINITION_BYTES / 1e6:.0f} MB")
    try:
        data = json.loads(raw)
    except (TypeError, ValueError, RecursionError) as e:
        raise SweepError("the store's sweep definition is not valid JSON") from e
    return check_definition(data), bool(root.attrs.get("metrics_pickle"))


def _bad(entry, what, found=None):
    shown = None if found is None else repr(found)[:80]
    return SweepError(f"the store's sweep definition: '{entry}' {what}", found=shown,
                      hint="this store was not written by avblocks or was changed; "
                           "re-create it with av.sweep(...)")


def _text(v, entry, limit=200):
    if not isinstance(v, str) or not 0 < len(v) <= limit or "\x00" in v:
        raise _bad(entry, f"must be a text of 1 to {limit} characters", v)
    return v


def _count(n, entry, lo, hi):
    if isinstance(n, bool) or not isinstance(n, int) or not lo <= n <= hi:
        raise _bad(entry, f"must be a whole number from {lo} to {hi}", n)
    return n


def _scenario(src, version):
    if not isinstance(src, dict):
        raise _bad("scenario", "must be a mapping", src)
    kind = src.get("kind")
    if kind not in SCENARIO_KINDS:
        raise _bad("scenario.kind", f"must be one of {list(SCENARIO_KINDS)}", kind)
    name = _text(src.get("name"), "scenario.name")
    if kind == "builtin":
        return {"name": name, "kind": kind}
    path = _text(src.get("path"), "scenario.path", 4096)
    out = {"name": name, "kind": kind, "path": path}
    if version == 1 or "text" in src and "sha256" not in src:
        text = src.get("text")
        if not isinstance(text, str) or len(text) > MAX_DEFINITION_BYTES:
            raise _bad("scenario.text", "must be the scenario file's text", type(text).__name__)
        out["sha256"] = sha256_of(text.encode("utf-8"))
        if kind == "py":          # avblocks <= 0.3 kept the text: never run, only hashed
            out["text_newlines"] = True
            return out
    else:
        sha = src.get("sha256")
        if not isinstance(sha, str) or not re.fullmatch(r"[0-9a-f]{64}", sha):
            raise _bad("scenario.sha256", "must be 64 hexadecimal digits", sha)
        out["sha256"] = sha
    if kind != "py":
        text = src.get("text")
        if not isinstance(text, str) or len(text) > MAX_DEFINITION_BYTES:
            raise _bad("scenario.text", "must be the scenario file's text",
                       type(text).__name__)
        out["text"] = text
    return out


def check_definition(data) -> dict:
    """A stored sweep definition, checked entry by entry before anything
    uses it: known version, a scenario of a known kind (a ``.py`` one by
    path and SHA-256 only; the text a 0.1-0.3 store kept for it is dropped,
    never run), grid names and values as plain JSON within the scenario
    limits, distinct integer seeds, at most :data:`MAX_CASES` cases,
    metric names and ``"module:function"`` references, log settings.
    Returns the definition rebuilt from the checked entries only; a
    :class:`SweepError` naming the entry otherwise."""
    from ..core.errors import ScenarioError
    from ..scenarios.limits import check_values
    from .spec import _METRIC_REF, normalise_grid, normalise_seeds
    if not isinstance(data, dict):
        raise SweepError("the store's sweep definition is not a mapping")
    version = data.get("version", 1)
    if version not in READABLE_VERSIONS:
        newer = isinstance(version, int) and not isinstance(version, bool) \
            and version > SPEC_VERSION
        raise SweepError(f"the store's sweep definition has version {version!r:.20}; this "
                         f"avblocks reads versions {list(READABLE_VERSIONS)}",
                         hint="upgrade avblocks" if newer else
                         "re-create the sweep with av.sweep(...)")
    try:
        check_values({k: data.get(k) for k in ("grid", "fixed", "log", "metrics",
                                               "metric_refs")}, "the store's definition")
    except ScenarioError as e:
        raise SweepError(str(e)) from None
    out = {"version": SPEC_VERSION, "scenario": _scenario(data.get("scenario"), version)}
    seeds = data.get("seeds")
    if isinstance(seeds, list) and not all(type(x) is int for x in seeds):
        raise _bad("seeds", "seeds must be whole numbers", seeds)
    try:
        out["grid"] = normalise_grid(data.get("grid") or {})
        out["seeds"] = normalise_seeds(data.get("seeds"))
        fixed = normalise_grid({k: [v] for k, v in (data.get("fixed") or {}).items()}) \
            if isinstance(data.get("fixed") or {}, dict) else None
    except SweepError as e:
        raise _bad("grid/seeds/fixed", str(e)) from None
    if fixed is None:
        raise _bad("fixed", "must be a mapping", data.get("fixed"))
    out["fixed"] = {k: v[0] for k, v in fixed.items()}
    for k in (*out["grid"], *out["fixed"]):
        _text(k, "grid", 1000)
    n = math.prod(len(v) for v in out["grid"].values()) * len(out["seeds"])
    if n > MAX_CASES:
        raise _bad("grid", f"describes {n:,} cases, more than {MAX_CASES:,}")
    metrics = data.get("metrics")
    if not isinstance(metrics, list) or not metrics or len(metrics) > 1000:
        raise _bad("metrics", "must be a list of 1 to 1,000 names", metrics)
    for m in metrics:
        if not isinstance(m, str) or not _NAME.match(m):
            raise _bad("metrics", "names are texts of 1 to 200 characters without '/'", m)
    if len(set(metrics)) != len(metrics):
        raise _bad("metrics", "repeats a name", metrics)
    out["metrics"] = list(metrics)
    refs = data.get("metric_refs") or {}
    if not isinstance(refs, dict):
        raise _bad("metric_refs", "must be a mapping", refs)
    for k, ref in refs.items():
        if k not in metrics:
            raise _bad("metric_refs", "names a metric the sweep does not have", k)
        if ref is not None and not (isinstance(ref, str) and len(ref) <= 300
                                    and _METRIC_REF.match(ref)):
            raise _bad(f"metric_refs.{k}", "must be 'package.module:function' or null", ref)
    out["metric_refs"] = dict(refs)
    log = data.get("log")
    if log is not None and not (isinstance(log, list) and len(log) <= 10_000 and all(
            isinstance(p, str) and 0 < len(p) <= 1000 for p in log)):
        raise _bad("log", "must be null or a list of port names", log)
    out["log"] = log
    out["log_every"] = _count(data.get("log_every", 1), "log_every", 1, 10**9)
    ens = data.get("ensemble", False)
    if not isinstance(ens, bool):
        raise _bad("ensemble", "must be true or false", ens)
    out["ensemble"] = ens
    token = data.get("token")
    if not isinstance(token, str) or not re.fullmatch(r"[0-9a-f]{1,64}", token):
        raise _bad("token", "must be a short hexadecimal text", token)
    out["token"] = token
    return out


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


def _check_case_metadata(root):
    """Refuse a local store whose case groups' metadata files are larger
    than :data:`MAX_CASE_METADATA_BYTES` before zarr parses them (a case's
    record is a few kB; a 314 MB store of two padded records took 1.9 GB
    and 42 s to open before, attack42)."""
    folder = getattr(getattr(root, "store", None), "root", None)
    if folder is None:
        return
    cases = Path(str(folder)) / (root.store_path.path or "") / "cases"
    try:
        entries = list(os.scandir(cases))
    except OSError:
        return
    for e in entries:
        if not _CASE.match(e.name):
            continue
        for meta in (Path(e.path) / "zarr.json", Path(e.path) / "metrics" / "zarr.json",
                     Path(e.path) / "logs" / "zarr.json"):
            try:
                size = meta.stat().st_size
            except OSError:
                continue
            if size > MAX_CASE_METADATA_BYTES:
                raise SweepError(f"case '{e.name}' of the store has {size / 1e6:.1f} MB of "
                                 f"metadata ({meta.name}), more than "
                                 f"{MAX_CASE_METADATA_BYTES / 1e6:.0f} MB",
                                 hint="a case's record is a few kB, never larger than "
                                      "the sweep's definition; this store was not "
                                      "written by avblocks or was changed")


def scan_cases(root, n_cases=None) -> dict:
    """``{case_id: attrs}`` of every case group that has a status: groups
    named ``c`` and seven to nine digits only, below ``n_cases`` when
    given; a status other than done or failed counts as failed. A local
    store's case metadata is size-checked before it is parsed."""
    out = {}
    if "cases" not in root:
        return out
    _check_case_metadata(root)
    for name, g in root["cases"].groups():
        m = _CASE.match(name)
        if m is None:
            continue
        cid = int(m.group(1))
        if n_cases is not None and cid >= n_cases:
            continue
        attrs = dict(g.attrs)
        if "status" in attrs:
            if attrs["status"] not in ("done", "failed"):
                attrs = {**attrs, "status": "failed",
                         "error": f"unknown status {str(attrs['status'])[:40]!r}"}
            if not isinstance(attrs.get("error", ""), str):
                attrs["error"] = str(attrs["error"])[:4000]
            out[cid] = attrs
    return out


def _checked(a, name, limit):
    """The values of array ``a`` once its data type (numbers, booleans) and
    codecs (:data:`SAFE_CODECS`), its size (at most ``limit`` values) and
    every stored chunk (it inflates to no more than its own size: no
    compression bomb) are checked (:func:`avblocks.core.stored.check_zarr_array`):
    a store cannot make avblocks decode with another codec or allocate
    without bound."""
    from ..core.stored import StoredArrayError, check_zarr_array
    md = a.metadata
    codecs = [c.to_dict().get("name") for c in getattr(md, "codecs", ())]
    if getattr(md, "zarr_format", None) != 3 or not set(codecs) <= SAFE_CODECS:
        raise SweepError(f"stored array '{name}' uses codecs {codecs}, not only "
                         f"{sorted(SAFE_CODECS)}")
    if np.dtype(a.dtype).kind not in "biuf":
        raise SweepError(f"stored array '{name}' holds {a.dtype}, not numbers")
    size = math.prod(a.shape)
    if size > limit:
        raise SweepError(f"stored array '{name}' has {size:,} values, more than {limit:,}")
    try:
        check_zarr_array(a, f"stored array '{name}'", max_values=limit)
        return np.asarray(a[...])
    except StoredArrayError as e:
        raise SweepError(str(e)) from None
    except (ValueError, TypeError, KeyError, OSError, RuntimeError) as e:
        raise SweepError(f"stored array '{name}' cannot be read: {type(e).__name__}: "
                         f"{str(e)[:200]}") from None


def read_metrics(root, case_id) -> dict:
    g = root["cases"][case_name(case_id)]
    if "metrics" not in g:
        return {}
    return {k: _checked(a, f"{case_name(case_id)}/metrics/{k}", MAX_METRIC_VALUES)
            for k, a in g["metrics"].arrays()}


def read_logs(root, case_id) -> dict:
    from ..scenarios.limits import memory_limit
    g = root["cases"][case_name(case_id)]
    if "logs" not in g:
        return {}
    return {k: _checked(a, f"{case_name(case_id)}/logs/{k}", memory_limit() // 8)
            for k, a in g["logs"].arrays()}
