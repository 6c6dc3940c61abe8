"""Arrays in files someone else made are data (issue 42): a Zarr store
whose array asks for Python's pickle to decode it (the ``pickle`` object
codec of Zarr v2, the way zarr-python 2 stored object arrays) is refused
by the reader, and the object inside, which writes a marker file when it
is unpickled, is never built: not by ``avblocks.Results.load``, not by a
sweep store's reader."""

from __future__ import annotations

import json
import pickle
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
