"""A folder opened once and files reached through it (core/confined.py), in
both of its ways: by descriptor (Linux, macOS) and the real-path fallback
Windows uses, forced here with ``dir_fd=False``.

Truth: the file system as ``os.lstat``/``os.walk`` see it afterwards (what
exists outside the folder, which files are whole, which temporaries are
left), never the module's own answers.
"""

from __future__ import annotations

import os
import threading
import time

import pytest

from avblocks.core import confined as cf
from avblocks.core.confined import Confined, FolderError
from avblocks.scenarios.document import load_document, save_document

MODES = [pytest.param(True, id="dir_fd"), pytest.param(False, id="fallback")]


@pytest.fixture(params=MODES)
def folder(request, tmp_path):
    if request.param and not cf.DIR_FD:
        pytest.skip("this system has no dir_fd: the fallback is its way")
    root = tmp_path / "root"
    root.mkdir()
    c = Confined(root, dir_fd=request.param)
    assert c.by_fd is request.param
    yield c
    c.close()


def _all(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder)
                  for d, dirs, files in os.walk(folder) for f in files + dirs)


@pytest.mark.parametrize("path, kind", [
    ("../x", "OutsideFolder"), ("a/../../x", "OutsideFolder"), ("/elsewhere/x", "OutsideFolder"),
    ("a\x00b", "BadPath"), ("n" * 256, "BadPath"), ("é" * 128, "BadPath"),
    ("a/" * 33 + "x", "BadPath"), ("x" * 1025, "BadPath"), ("", "BadPath"), ("  ", "BadPath"),
    (5, "BadPath"), (None, "BadPath"), (b"x", "BadPath"), ("\udcff\ud800", "BadPath"),
])
def test_paths_are_refused_by_name_before_anything_is_opened(tmp_path, path, kind):
    with pytest.raises(FolderError) as e:
        cf.split(path, tmp_path)
    assert e.value.kind == kind


def test_dots_are_taken_as_names_say(tmp_path):
    assert cf.split("a/./b/../c.yaml", tmp_path) == ("a", "c.yaml")
    assert cf.split(str(tmp_path / "a" / "b.yaml"), tmp_path) == ("a", "b.yaml")
    assert cf.split("n" * 255, tmp_path) == ("n" * 255,)
    assert cf.split("a/" * 31 + "x", tmp_path) == ("a",) * 31 + ("x",)


def test_writes_are_whole_and_leave_no_temporary(folder):
    folder.write_atomic(("a", "b", "x.yaml"), b"one\n")
    assert (folder.root / "a" / "b" / "x.yaml").read_bytes() == b"one\n"
    folder.write_atomic(("a", "b", "x.yaml"), b"two\n")
    assert (folder.root / "a" / "b" / "x.yaml").read_bytes() == b"two\n"
    with pytest.raises(FolderError) as e:
        folder.write_atomic(("a", "b", "x.yaml"), b"three\n", exclusive=True)
    assert e.value.kind == "Exists"
    assert (folder.root / "a" / "b" / "x.yaml").read_bytes() == b"two\n"
    folder.write_atomic(("a", "new.yaml"), b"new\n", exclusive=True)
    assert folder.read_bytes(("a", "new.yaml"), 100) == b"new\n"
    with pytest.raises(FolderError) as e:
        folder.write_atomic(("a",), b"x")                 # a folder is not replaced
    assert e.value.kind == "BadPath"
    assert _all(folder.root) == ["a", "a/b", "a/b/x.yaml", "a/new.yaml"]


def test_links_are_never_followed(folder, tmp_path):
    out = tmp_path / "outside"
    out.mkdir()
    (out / "secret.yaml").write_text("secret")
    os.symlink(out, folder.root / "door")
    os.symlink(out / "secret.yaml", folder.root / "s.yaml")
    (folder.root / "real").mkdir()
    (folder.root / "real" / "mine.yaml").write_text("mine")
    for parts in (("door", "secret.yaml"), ("s.yaml",)):
        with pytest.raises(FolderError) as e:
            folder.read_bytes(parts, 1000)
        assert e.value.kind == "OutsideFolder", parts
    for parts in (("door", "x.yaml"), ("door", "sub", "x.yaml")):
        with pytest.raises(FolderError) as e:
            folder.write_atomic(parts, b"x")
        assert e.value.kind == "OutsideFolder"
    assert sorted(os.listdir(out)) == ["secret.yaml"]
    assert folder.listing((".yaml",)) == [("real", "mine.yaml")]
    # a tree removed with a link inside: the link goes, what it points to stays
    os.symlink(out, folder.root / "real" / "inner")
    folder.remove_tree(("real",))
    assert not (folder.root / "real").exists()
    assert (out / "secret.yaml").read_text() == "secret"


def test_a_file_over_the_limit_a_fifo_and_a_folder_are_not_read(folder):
    (folder.root / "big.yaml").write_bytes(b"x" * 2000)
    if hasattr(os, "mkfifo"):                # (not on Windows)
        os.mkfifo(folder.root / "pipe.yaml")
    (folder.root / "dir.yaml").mkdir()
    fifo = (("pipe.yaml",), "BadPath") if hasattr(os, "mkfifo") else (("x",), "NotFound")
    for parts, kind in ((("big.yaml",), "TooLarge"), fifo,
                        (("dir.yaml",), "BadPath"), (("none.yaml",), "NotFound"),
                        (("no", "none.yaml"), "NotFound")):
        with pytest.raises(FolderError) as e:
            folder.read_bytes(parts, 1000)
        assert e.value.kind == kind, parts
    assert folder.read_bytes(("big.yaml",), 2000) == b"x" * 2000


def test_close_removes_the_temporaries_being_written(folder):
    """What SIGTERM does in ``avblocks edit``: the editor closes its folder
    while a write is under way (a writer stopped between its temporary and
    the rename); the temporary goes, the file is never half there."""
    started, go_on = threading.Event(), threading.Event()
    original = folder._os.replace

    def slow_replace(h, src, dst):
        started.set()
        go_on.wait(10)
        return original(h, src, dst)

    folder._os.replace = slow_replace
    errors = []

    def write():
        try:
            folder.write_atomic(("x.yaml",), b"whole\n")
        except FolderError as e:
            errors.append(e)

    t = threading.Thread(target=write)
    t.start()
    assert started.wait(10)
    assert [f for f in os.listdir(folder.root) if ".part" in f]    # it is there now
    assert folder.pending()
    folder.close()
    assert not [f for f in os.listdir(folder.root) if ".part" in f]
    go_on.set()
    t.join(10)
    assert not (folder.root / "x.yaml").exists() and len(errors) == 1


def test_an_interrupt_while_writing_leaves_nothing(folder):
    class Stop(KeyboardInterrupt):
        pass

    original = folder._os.replace

    def interrupted(h, src, dst):
        raise Stop

    folder._os.replace = interrupted
    with pytest.raises(Stop):
        folder.write_atomic(("x.yaml",), b"x")
    folder._os.replace = original
    assert _all(folder.root) == []


def test_documents_save_and_load_through_either_way(folder):
    doc = load_document("waypoints")["document"]
    saved = save_document("mine/w.yaml", doc, folder, origin="waypoints")
    got = load_document("mine/w.yaml", root=folder)
    assert got["revision"] == saved["revision"] and got["path"] == "mine/w.yaml"
    assert got["document"]["blocks"] == doc["blocks"]
    with pytest.raises(FolderError) as e:
        save_document("mine/w.yaml", doc, folder, create=True)
    assert e.value.kind == "Exists"
    assert _all(folder.root) == ["mine", "mine/w.yaml"]


def test_the_race_on_either_way_lands_nothing_outside(folder, tmp_path):
    """A folder swapped for a link out while 200 writes go into it. By
    descriptor nothing can land outside; the fallback checks after each
    open and removes what it finds outside, so nothing stays there."""
    out = tmp_path / "outside"
    out.mkdir()
    sub = folder.root / "sub"
    sub.mkdir()
    stop = threading.Event()

    def swap():
        n = 0
        while not stop.is_set():
            n += 1
            aside = folder.root / f"sub.{n}"
            try:
                os.rename(sub, aside)
            except OSError:
                continue
            try:
                os.symlink(out, sub)
            except FileExistsError:        # a write made 'sub' anew in the gap
                continue
            time.sleep(0.0003)
            os.unlink(sub)
            try:
                os.rename(aside, sub)
            except OSError:
                pass
            time.sleep(0.002)

    t = threading.Thread(target=swap, daemon=True)
    t.start()
    refused = 0
    try:
        for i in range(200):
            try:
                folder.write_atomic(("sub", f"f{i}.yaml"), b"whole\n")
            except FolderError as e:
                assert e.kind in ("OutsideFolder", "NotFound", "IOError"), e
                refused += 1
    finally:
        stop.set()
        t.join(10)
    leftover = _all(out)
    if folder.by_fd:
        assert leftover == []
        assert not [f for f in _all(folder.root) if ".part" in f]
    else:
        # the fallback checks after the fact: a temporary may be stranded by
        # a swap between its check and its use, but no file lands outside
        assert [f for f in leftover if ".part" not in f] == [], leftover
    folder.write_atomic(("sub", "after.yaml"), b"whole\n")     # and it still writes
    assert (folder.root / "sub" / "after.yaml").read_bytes() == b"whole\n"
    print(f"\n{200 - refused} of 200 writes landed during the swaps")


def test_trim_memory_and_stop_signals_have_their_fallbacks():
    import signal
    import sys
    assert cf.trim_memory() is sys.platform.startswith("linux")
    sigs = cf.stop_signals()
    assert signal.SIGINT in sigs and signal.SIGTERM in sigs
    assert (getattr(signal, "SIGHUP", None) in sigs) is hasattr(signal, "SIGHUP")
