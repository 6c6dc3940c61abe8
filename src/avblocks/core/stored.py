"""Arrays in files someone else made, checked before they are read: what a
results file (NetCDF/HDF5, Zarr) or a sweep store declares is never taken
on trust.

A small file can make a reader allocate far more than it holds, or read
other files:

* a **declared shape** with no data behind it (Zarr and HDF5 fill the
  missing chunks with the fill value): a 2 kB Zarr store made
  ``Results.load`` allocate 11 GB;
* a **compression bomb**: a chunk declared as 10 values whose compressed
  stream inflates to gigabytes (zlib, gzip, zstd and blosc all allocate
  what the stream produces or declares before the chunk's size is
  compared): a 1.5 MB chunk took 3.2 GB in a sweep store, a 1 MB HDF5
  chunk 1 GB;
* **HDF5 links and external storage**: an external link (another HDF5
  file), a dataset stored in an external raw file (``/dev/zero``,
  ``~/.ssh/id_rsa``) or a virtual dataset read data from outside the
  file; a results file read that way carried another file's bytes.

:func:`check_zarr_array` and :func:`check_hdf5` refuse all of these with
an :class:`~avblocks.core.errors.AvError` naming the array, before any
array data is decoded: declared sizes within :func:`memory_limit`, only
plain codecs, every stored chunk's compressed stream checked to inflate
to at most the chunk's own size (decompressed in bounded pieces, or its
header read: zstd's frame content size, blosc's ``nbytes``), no links,
no external or virtual storage. A chunk changed between the check and the
read is not covered (the file is read twice, not held).
"""

from __future__ import annotations

import math
import zlib

import numpy as np

from .errors import AvError
from .memlimit import describe, memory_limit

#: Zarr v3 codecs whose arrays are read (what zarr and xarray write for
#: numbers and text); anything else is refused before reading.
ZARR_CODECS = frozenset({"bytes", "transpose", "zstd", "gzip", "blosc", "crc32c",
                         "vlen-utf8"})
#: Zarr v2 compressors read (``compressor.id``); filters only ``vlen-utf8``.
ZARR2_COMPRESSORS = frozenset({"zstd", "gzip", "zlib", "blosc"})
#: HDF5 filters read: deflate (1), shuffle (2), fletcher32 (3).
HDF5_FILTERS = {1: "deflate", 2: "shuffle", 3: "fletcher32"}
#: Most chunks one array may have (each is checked before it is read).
MAX_CHUNKS = 1_000_000
_PIECE = 1 << 20


class StoredArrayError(AvError):
    """An array in a file someone else made that avblocks does not read."""


# ------------------------------------------------------------ streams
def _inflate_size(raw: bytes, bound: int, wbits: int) -> int:
    """Bytes a zlib/gzip stream (members one after another) inflates to,
    counted in pieces of at most 1 MB and stopped past ``bound``."""
    total, data = 0, raw
    while data:
        d = zlib.decompressobj(wbits)
        try:
            while data:
                out = d.decompress(data, _PIECE)
                total += len(out)
                if total > bound:
                    return total
                data = d.unconsumed_tail
                if d.eof:
                    break
        except zlib.error:
            break                       # not (or no more) a stream: the codec says so
        if not d.eof:
            break                       # truncated: the codec will say so
        data = d.unused_data
        if wbits == 15 or len(data) < 18:   # zlib: one stream; a checksum after it
            break
    return total


def _zstd_size(raw: bytes):
    """The content size a zstd frame declares, or None when it declares none
    (zstd format, RFC 8878, section 3.1.1.1)."""
    if len(raw) < 6 or raw[:4] != b"\x28\xb5\x2f\xfd":
        return None
    fhd = raw[4]
    fcs_flag, single, dict_flag = fhd >> 6, (fhd >> 5) & 1, fhd & 3
    pos = 5 + (0 if single else 1) + (0, 1, 2, 4)[dict_flag]
    size = (1 if single else 0, 2, 4, 8)[fcs_flag]
    if size == 0 or len(raw) < pos + size:
        return None
    value = int.from_bytes(raw[pos:pos + size], "little")
    return value + 256 if size == 2 else value


def decoded_size(codec: str, raw: bytes, bound: int) -> int | None:
    """How many bytes ``raw`` (a chunk compressed with ``codec``) decodes
    to, as far as needed to compare with ``bound``; None when the stream
    cannot tell (a zstd frame without its size)."""
    if codec in ("gzip", "zlib"):
        return _inflate_size(raw, bound, 47 if codec == "gzip" else 15)
    if codec == "zstd":
        return _zstd_size(raw)
    if codec == "blosc":
        return int.from_bytes(raw[4:8], "little") if len(raw) >= 16 else None
    if codec == "deflate":
        return _inflate_size(raw, bound, 15)
    return len(raw)


def _refuse(what, why, found=None):
    return StoredArrayError(f"{what}: {why}", found=found,
                            hint="this file was not written by avblocks, or was changed; "
                                 "nothing of it was decoded")


# ------------------------------------------------------------ Zarr
def _zarr_codecs(a):
    """``(names, compressor or None)`` of a Zarr array's codec chain."""
    md = a.metadata
    if getattr(md, "zarr_format", None) == 2:
        comp = getattr(md, "compressor", None)
        names = [f"v2:{getattr(f, 'codec_id', f)}" for f in (md.filters or ())]
        cid = None if comp is None else getattr(comp, "codec_id", str(comp))
        return names + ([cid] if cid else []), cid, 2
    names = [c.to_dict().get("name") for c in getattr(md, "codecs", ())]
    comp = [n for n in names if n in ("zstd", "gzip", "blosc")]
    return names, (comp[0] if len(comp) == 1 else comp or None), 3


def check_zarr_array(a, what, max_values=None, texts=False):
    """Refuse the Zarr array ``a`` unless reading it is bounded: plain codecs
    (:data:`ZARR_CODECS`; Zarr v2: :data:`ZARR2_COMPRESSORS`), at most one
    compressor, a numeric (``texts``: or text) data type, at most
    ``max_values`` values (default: what :func:`memory_limit` holds) and
    :data:`MAX_CHUNKS` chunks, and every stored chunk inflating to at most
    its own size. ``what`` names the array in the message."""
    names, comp, fmt = _zarr_codecs(a)
    if fmt == 3:
        bad = sorted(set(map(str, names)) - ZARR_CODECS)
    else:
        bad = sorted({n for n in names if n != "v2:vlen-utf8" and n not in ZARR2_COMPRESSORS})
    if bad or isinstance(comp, list):
        raise _refuse(what, f"uses codecs {names}; avblocks reads only "
                            f"{sorted(ZARR_CODECS)} with at most one compressor")
    dt = np.dtype(a.dtype) if not str(a.dtype).startswith(("<U", "|O", "str", "object")) \
        else None
    kind = dt.kind if dt is not None else "U"
    if kind not in "biuf" and not (texts and kind in "USO"):
        raise _refuse(what, f"holds {a.dtype}, not numbers")
    size = math.prod(a.shape)
    item = dt.itemsize if dt is not None and kind in "biuf" else 1
    limit = memory_limit() // max(item, 1) if max_values is None else max_values
    if size > limit:
        raise _refuse(what, f"has {size:,} values, more than {limit:,}")
    chunk_shape = getattr(a, "chunks", None) or a.shape
    nchunks = math.prod(math.ceil(s / max(c, 1)) for s, c in zip(a.shape, chunk_shape)) \
        if a.shape else 1
    if nchunks > MAX_CHUNKS:
        raise _refuse(what, f"has {nchunks:,} chunks, more than {MAX_CHUNKS:,}")
    if comp is None:
        return
    per_chunk = math.prod(chunk_shape) * item if kind in "biuf" else memory_limit()
    per_chunk += 4 * names.count("crc32c")          # a checksum inside the compressed part
    for key, raw in _chunks(a):
        if raw is None:
            continue
        got = decoded_size(comp, raw, per_chunk)
        if got is None:
            raise _refuse(what, f"chunk '{key}' does not say how large it is ({comp})")
        if got > per_chunk:
            raise _refuse(what, f"chunk '{key}' inflates to more than its "
                                f"{per_chunk:,} bytes ({comp}, a compression bomb)")


def _chunks(a):
    """``(key, stored bytes)`` of every chunk of ``a`` that is stored."""
    from zarr.core.buffer import default_buffer_prototype
    from zarr.core.sync import sync
    store, prefix = a.store_path.store, a.store_path.path.rstrip("/")
    prefix = prefix + "/" if prefix else ""

    async def keys():
        return [k async for k in store.list_prefix(prefix)]
    meta = {"zarr.json", ".zarray", ".zattrs", ".zgroup", ".zmetadata"}
    for key in sync(keys()):
        if key.rsplit("/", 1)[-1] in meta:
            continue
        buf = sync(store.get(key, prototype=default_buffer_prototype()))
        yield key, (None if buf is None else buf.to_bytes())


def check_zarr_group(group, what, texts=True):
    """:func:`check_zarr_array` for every array under ``group``, and their
    declared sizes together within :func:`memory_limit`."""
    total = 0
    for name, a in group.arrays():
        check_zarr_array(a, f"{what}: array '{name}'", texts=texts)
        total += math.prod(a.shape) * (a.dtype.itemsize if hasattr(a.dtype, "itemsize")
                                       and a.dtype.kind in "biuf" else 8)
    for name, g in group.groups():
        total += check_zarr_group(g, f"{what}/{name}", texts)
    if total > memory_limit():
        raise _refuse(what, f"its arrays declare {describe(total)}")
    return total


# ------------------------------------------------------------ HDF5
def check_hdf5(path, what=None):
    """Refuse the HDF5 (NetCDF-4) file at ``path`` unless every object in it
    is reached by a hard link and every dataset is stored in the file itself
    with only :data:`HDF5_FILTERS`, its chunks inflate to at most their own
    size, and all datasets together declare at most :func:`memory_limit`
    bytes."""
    import h5py
    what = what or str(path)
    total = 0
    with h5py.File(path, "r") as f:
        names: list = []
        f.visit_links(names.append)
        for name in names:
            link = f.get(name, getlink=True)
            if not isinstance(link, h5py.HardLink):
                raise _refuse(what, f"'{name}' is a {type(link).__name__} (data from "
                                    "outside the file)")
            obj = f[name]
            if not isinstance(obj, h5py.Dataset):
                continue
            if obj.external:
                raise _refuse(what, f"dataset '{name}' is stored in other files",
                              found=[str(e[0])[:80] for e in obj.external][:3])
            if obj.is_virtual:
                raise _refuse(what, f"dataset '{name}' is a virtual dataset (data from "
                                    "other files)")
            item = obj.dtype.itemsize if obj.dtype.kind in "biufc" else 16
            total += int(obj.size or 0) * item
            _check_hdf5_chunks(obj, f"{what}: dataset '{name}'")
    if total > memory_limit():
        raise _refuse(what, f"its datasets declare {describe(total)}")


def _check_hdf5_chunks(d, what):
    dcpl = d.id.get_create_plist()
    filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())]
    bad = [f for f in filters if f not in HDF5_FILTERS]
    if bad:
        raise _refuse(what, f"uses HDF5 filters {bad}; avblocks reads only "
                            f"{sorted(HDF5_FILTERS.values())}")
    if 1 not in filters or d.chunks is None:
        return
    per_chunk = math.prod(d.chunks) * (d.dtype.itemsize if d.dtype.kind in "biufc" else 16)
    n = d.id.get_num_chunks()
    if n > MAX_CHUNKS:
        raise _refuse(what, f"has {n:,} chunks, more than {MAX_CHUNKS:,}")
    for i in range(n):
        info = d.id.get_chunk_info(i)
        mask, raw = d.id.read_direct_chunk(info.chunk_offset)
        if mask & 1:                    # deflate skipped for this chunk
            continue
        got = decoded_size("deflate", raw, per_chunk + 4)
        if got > per_chunk + 4:
            raise _refuse(what, f"chunk {i} inflates to more than its {per_chunk:,} "
                                "bytes (deflate, a compression bomb)")


__all__ = ["check_zarr_array", "check_zarr_group", "check_hdf5", "decoded_size",
           "StoredArrayError", "ZARR_CODECS", "HDF5_FILTERS", "MAX_CHUNKS"]
