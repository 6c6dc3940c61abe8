"""Arrays in files someone else made are data (issue 42): a Zarr store
whose array asks for Python's pickle to decode it (the ``pickle`` object
codec of Zarr v2, the way zarr-python 2 stored object arrays) is refused
by the reader, and the object inside, which writes a marker file when it
is unpickled, is never built: not by ``avblocks.Results.load``, not by a
sweep store's reader. And what a file declares (an array's shape, a
compressed chunk's size, HDF5 links and external storage, a policy zip's
members) is checked before anything is decoded."""

from __future__ import annotations

import json
import pickle
import re
import zlib
from pathlib import Path

import pytest

pytest.importorskip("zarr")


class _Marker:
    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (Path(self.path).write_text, ("pwned",))


def _pickle_store(folder, marker, name="x"):
    """A Zarr v2 group holding one object array whose only chunk is a pickle."""
    root = Path(folder)
    (root / name).mkdir(parents=True)
    (root / ".zgroup").write_text(json.dumps({"zarr_format": 2}))
    (root / ".zattrs").write_text(json.dumps({}))
    (root / name / ".zarray").write_text(json.dumps({
        "zarr_format": 2, "shape": [1], "chunks": [1], "dtype": "|O", "compressor": None,
        "fill_value": 0, "order": "C", "filters": [{"id": "pickle", "protocol": 5}],
        "dimension_separator": "."}))
    (root / name / ".zattrs").write_text(json.dumps({"_ARRAY_DIMENSIONS": ["t"]}))
    (root / name / "0").write_bytes(pickle.dumps([_Marker(marker)]))
    return root


def test_results_load_never_unpickles_an_array(tmp_path):
    import avblocks as av
    marker = tmp_path / "pwned.txt"
    store = _pickle_store(tmp_path / "r.zarr", marker)
    with pytest.raises(Exception):  # noqa: B017 - the reader refuses the codec, any way
        av.Results.load(store)
    assert not marker.exists()


def test_a_sweep_store_in_zarr_v2_is_not_opened(tmp_path):
    from avblocks.sweep import SweepError
    from avblocks.sweep.store import open_store
    marker = tmp_path / "pwned.txt"
    store = _pickle_store(tmp_path / "s.zarr", marker)
    (store / ".zattrs").write_text(json.dumps({"avblocks_sweep": "{}"}))
    with pytest.raises(SweepError, match="no sweep store"):
        open_store(store)
    assert not marker.exists()


# --------------------------------------------------- what a file declares
# (attack42) Before: a 2 kB Zarr results store declaring 2.4e9 values made
# Results.load allocate 11 GB; a NetCDF file whose dataset lives in an
# external raw file read that file (a secret came back as data); an HDF5
# external link read another file; a 1 MB deflate chunk declared as 10
# values inflated to 1 GB; a 1.5 MB gzip chunk in a sweep store took 3.2 GB
# and ended in NumPy's ValueError; a 1.9 MB policy .npz inflated to 4.2 GB.
# Truth: the refusal names what the file declares, the secret never
# appears, and the peak memory of a separate process reading the bomb (its
# kernel-counted ru_maxrss) stays far below what the bomb inflates to.

BOMB = 512 * 1024**2             # bytes a bomb inflates to
linux_only = pytest.mark.skipif(not Path("/proc/self/status").exists(),
                                reason="peak memory from /proc (Linux)")


def _zeros_deflated(n, wbits=15):
    co = zlib.compressobj(1, zlib.DEFLATED, wbits)
    piece = b"\0" * (16 << 20)
    return b"".join([co.compress(piece) for _ in range(n // len(piece))] + [co.flush()])


def _peak_mb(code):
    """Peak resident memory [MB] of a fresh Python running ``code`` (which
    prints its own result), and that output. The kernel's high-water mark
    of the process's own memory (``VmHWM``, reset by exec, unlike
    ``ru_maxrss``, which keeps the forking parent's)."""
    import subprocess
    import sys
    src = str(Path(__file__).resolve().parents[2] / "src")
    tail = ("\nprint('PEAK', [l.split()[1] for l in open('/proc/self/status') "
            "if l.startswith('VmHWM')][0])")
    # a regression must fail here, not take the machine's memory
    head = ("import resource\n_s, _h = resource.getrlimit(resource.RLIMIT_AS)\n"
            "_cap = 6 * 1024**3 if _h == resource.RLIM_INFINITY else min(6 * 1024**3, _h)\n"
            "resource.setrlimit(resource.RLIMIT_AS, (_cap, _h))\n")
    run = subprocess.run([sys.executable, "-c", head + code + tail],
                         capture_output=True, text=True, timeout=300,
                         env={**__import__("os").environ, "PYTHONPATH": src})
    out = run.stdout
    assert "PEAK" in out, run.stderr[-800:]
    peak = int(out.rsplit("PEAK", 1)[1]) / 1024
    return peak, out.rsplit("PEAK", 1)[0], run.stderr


def _results(tmp_path):
    import numpy as np

    import avblocks as av
    res = av.Results(np.arange(3.0), {"fleet.pose": np.zeros((3, 2, 3))})
    return res.save(tmp_path / "good.nc"), res.save(tmp_path / "good.zarr")


@linux_only
def test_a_results_store_declaring_a_huge_array_is_refused_before_allocating(tmp_path,
                                                                             monkeypatch):
    import shutil

    import avblocks as av
    from avblocks.core.errors import AvError
    _nc, good = _results(tmp_path)
    huge = tmp_path / "huge.zarr"
    shutil.copytree(good, huge)
    root = json.loads((huge / "zarr.json").read_text())
    root.pop("consolidated_metadata", None)
    (huge / "zarr.json").write_text(json.dumps(root))
    for name in ("time", "fleet.pose"):
        meta = json.loads((huge / name / "zarr.json").read_text())
        meta["shape"][0] = 400_000_000
        meta["chunk_grid"]["configuration"]["chunk_shape"][0] = 1_000_000
        (huge / name / "zarr.json").write_text(json.dumps(meta))
        shutil.rmtree(huge / name / "c")
    monkeypatch.setenv("AVBLOCKS_MAX_MEMORY", "1e9")
    peak, out, err = _peak_mb(
        "import avblocks as av\n"
        f"try:\n    av.Results.load({str(huge)!r})\n"
        "except Exception as e:\n    print(type(e).__name__, e)")
    assert re.search(r"StoredArrayError .*array '(time|fleet.pose)': has [0-9,]+ values, "
                     r"more than 125,000,000", out), (out, err[-500:])
    assert peak < 400, peak                          # it declares 19 GB
    assert av.Results.load(good)["fleet.pose"].shape == (3, 2, 3)
    with pytest.raises(AvError, match=r"has [0-9,]+ values, more than 125,000,000"):
        av.Results.load(huge)


def test_a_netcdf_file_never_reads_other_files(tmp_path):
    import shutil

    import h5py

    import avblocks as av
    from avblocks.core.errors import AvError
    good, _zarr = _results(tmp_path)
    secret = tmp_path / "secret.txt"
    secret.write_text("SECRET-KEY-123\n" * 3)
    ext = tmp_path / "ext.nc"
    shutil.copy(good, ext)
    with h5py.File(ext, "r+") as f:
        attrs = dict(f["fleet.pose"].attrs)
        del f["fleet.pose"]
        d = f.create_dataset("fleet.pose", shape=(3, 2, 3), dtype="u1",
                             external=[(str(secret), 0, 18)])
        for k, v in attrs.items():
            if k not in ("DIMENSION_LIST",):
                d.attrs[k] = v
    assert bytes(h5py.File(ext, "r")["fleet.pose"][...].ravel()) == b"SECRET-KEY-123\nSEC"
    with pytest.raises(AvError, match="stored in other files") as e:
        av.Results.load(ext)
    assert "SECRET" not in str(e.value)
    link = tmp_path / "link.nc"
    shutil.copy(good, link)
    with h5py.File(link, "r+") as f:
        f["stolen"] = h5py.ExternalLink(str(good), "/fleet.pose")
    with pytest.raises(AvError, match="'stolen' is a ExternalLink"):
        av.Results.load(link)
    assert av.Results.load(good)["fleet.pose"].shape == (3, 2, 3)


@linux_only
def test_a_deflate_bomb_in_a_netcdf_file_is_refused_with_bounded_memory(tmp_path):
    import shutil

    import h5py
    good, _zarr = _results(tmp_path)
    bomb = tmp_path / "bomb.nc"
    shutil.copy(good, bomb)
    with h5py.File(bomb, "r+") as f:
        d = f.create_dataset("x", shape=(10,), dtype="f8", chunks=(10,), compression="gzip")
        d.id.write_direct_chunk((0,), _zeros_deflated(BOMB))
    with h5py.File(bomb, "r") as f:                  # HDF5 itself inflates it all
        assert f["x"][...].tolist() == [0.0] * 10
    peak, out, err = _peak_mb(
        "import avblocks as av\n"
        f"try:\n    av.Results.load({str(bomb)!r})\n"
        "except Exception as e:\n    print(type(e).__name__, e)")
    assert "StoredArrayError" in out and "compression bomb" in out, err[-500:]
    assert peak < 400, peak                          # the bomb is 512 MB


@linux_only
@pytest.mark.parametrize("codec", ["gzip", "zstd"])
def test_a_compression_bomb_in_a_sweep_store_is_refused_with_bounded_memory(tmp_path,
                                                                            codec):
    import numpy as np
    import zarr
    store = tmp_path / "s.zarr"
    g = zarr.open_group(str(store), mode="w", zarr_format=3)
    comp = zarr.codecs.GzipCodec() if codec == "gzip" else zarr.codecs.ZstdCodec()
    a = g.create_array("m", shape=(10,), dtype="f8", chunks=(10,), compressors=[comp])
    a[:] = np.arange(10.0)
    chunk = store / "m" / "c" / "0"
    if codec == "gzip":
        chunk.write_bytes(_zeros_deflated(BOMB, 31))
    else:
        import numcodecs
        chunk.write_bytes(numcodecs.Zstd(level=1).encode(b"\0" * BOMB))
    peak, out, err = _peak_mb(
        "import zarr\nfrom avblocks.sweep.store import _checked\n"
        f"a = zarr.open_group({str(store)!r}, mode='r')['m']\n"
        "try:\n    _checked(a, 'm', 10_000)\n"
        "except Exception as e:\n    print(type(e).__name__, e)")
    assert "SweepError" in out and "compression bomb" in out, (out, err[-500:])
    assert peak < 400, peak


def test_a_sweep_dataset_past_the_memory_limit_is_refused_before_allocating(tmp_path,
                                                                            monkeypatch):
    """A definition may declare 10^7 cases and one case a 10^4-value metric:
    the dataset (n_cases x values) is sized before it is allocated."""
    import numpy as np
    import zarr

    from avblocks.sweep import Study, SweepError
    from avblocks.sweep import store as sweep_store
    definition = {"version": 2, "scenario": {"name": "waypoints", "kind": "builtin"},
                  "grid": {"agents": list(range(2, 2002))}, "seeds": [0, 1], "fixed": {},
                  "metrics": ["m"], "log": None, "log_every": 1, "ensemble": False,
                  "metric_refs": {}, "token": "ab12"}
    out = tmp_path / "big.zarr"
    sweep_store.create_store(out, definition)
    sweep_store.write_case(out, 0, {"status": "done", "error": "", "wall_s": 0.1,
                                    "seed": 0, "values": {"agents": 2}},
                           metrics={"m": np.zeros(10_000)})
    monkeypatch.setenv("AVBLOCKS_MAX_MEMORY", "1e8")
    study = Study(out)
    assert study.counts() == {"done": 1, "failed": 0, "missing": 3999}
    with pytest.raises(SweepError, match=r"would take 0.32 GB, more than the 0.1 GB "
                                         r"limit .* at metric 'm' \(4,000 cases\)"):
        study.to_xarray()
    assert study.metrics(0)["m"].shape == (10_000,)        # one case still reads
    assert zarr.open_group(str(out))["cases/c0000000/metrics/m"].shape == (10_000,)


def test_a_policy_zip_bomb_is_refused_before_numpy_reads_it(tmp_path):
    import io
    import zipfile

    import numpy as np
    from numpy.lib import format as npformat

    from avblocks.controllers.policy import MAX_POLICY_BYTES, Policy
    from avblocks.core.errors import ParameterError
    n = (MAX_POLICY_BYTES // 8) + 1_000
    head = io.BytesIO()
    npformat.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False,
                                           "shape": (n,)})
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        with z.open("w0.npy", "w", force_zip64=True) as f:
            f.write(head.getvalue())
            left = n * 8
            while left > 0:
                f.write(b"\0" * min(left, 16 << 20))
                left -= 16 << 20
        meta = io.BytesIO()
        np.save(meta, np.array(json.dumps({"order": ["w0"], "activation": "tanh",
                                           "output": "clip", "act_dim": 2})))
        z.writestr("__meta__.npy", meta.getvalue())
    assert path.stat().st_size < 2e6                       # a 2 MB file ...
    declared = sum(i.file_size for i in zipfile.ZipFile(path).infolist())
    assert declared > MAX_POLICY_BYTES                    # ... that inflates past 256 MB
    with pytest.raises(ParameterError, match="inflate to .* MB, more than 268 MB"):
        Policy.load(path)
    for junk in (b"not a zip", b"PK\x03\x04junk"):
        (tmp_path / "junk.npz").write_bytes(junk)
        with pytest.raises(ParameterError, match="not a policy file"):
            Policy.load(tmp_path / "junk.npz")
    good = Policy({"w0": np.ones((3, 2)), "b0": np.zeros(2)}).save(tmp_path / "ok.npz")
    with zipfile.ZipFile(good, "a") as z:
        z.writestr("evil.pkl", b"x")
    with pytest.raises(ParameterError, match=".npy arrays only"):
        Policy.load(good)
