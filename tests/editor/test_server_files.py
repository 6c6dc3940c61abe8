"""The editor's files on a real server: nothing lands outside its folder, a
symbolic link is never followed out, a bad path is a JSON 400, and the
runs' folders live under the editor's folder and go with their runs.

Truth: the file system as ``os.walk``/``os.lstat`` see it after the
requests (what exists outside the folder, stray ``.part`` files), not the
server's answers.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

DOC = {"name": "tiny", "parameters": {"agents": 3, "seed": 1},
       "blocks": {"fleet": {"type": "vehicles.Unicycle",
                            "pose0": {"random_poses": {"n": "$agents", "area": [10, 10],
                                                       "seed": "$seed"}}},
                  "drive": {"type": "controllers.PointToPoint", "n": "$agents",
                            "waypoints": {"random_waypoints": {"n": "$agents", "count": 2,
                                                               "area": [10, 10],
                                                               "seed": "$seed"}}}},
       "wires": [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"]],
       "simulation": {"t_final": 0.5, "dt": 0.05}}


def _everything(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder)
                  for d, dirs, files in os.walk(folder) for f in files + dirs)


def test_a_folder_swapped_for_a_link_out_never_receives_a_save(editor_server,
                                                               tmp_path_factory):
    """Issue 42's race: while a thread swaps ``sub`` for a symbolic link to a
    folder outside and back, 400 saves into ``sub/`` run from four clients.
    Each save lands in the real ``sub`` or is refused; nothing is written
    outside, and no temporary ``.part`` file is left anywhere (before: 40
    of 400 landed outside, ~60 ``.part`` files stayed)."""
    srv = editor_server
    outside = tmp_path_factory.mktemp("outside")
    sub = srv.root / "sub"
    sub.mkdir()
    stop = threading.Event()
    swaps = [0]

    def swap():
        n = 0
        while not stop.is_set():
            n += 1
            aside = srv.root / f"sub.{n}"
            try:
                os.rename(sub, aside)
            except OSError:
                continue
            while True:
                try:
                    os.symlink(outside, sub)
                    break
                except FileExistsError:    # a save made 'sub' anew in the gap
                    n += 1
                    os.rename(sub, srv.root / f"sub.{n}")
            time.sleep(0.0005)
            os.unlink(sub)                 # still the link: a save never replaces one
            try:
                os.rename(aside, sub)
            except OSError:                # a save made 'sub' anew meanwhile
                pass
            swaps[0] += 1
            time.sleep(0.0005)

    def save(i):
        return srv.post("save", {"path": f"sub/d{i % 20}.yaml", "document": DOC,
                                 "draft": True})

    t = threading.Thread(target=swap, daemon=True)
    t.start()
    try:
        with ThreadPoolExecutor(4) as pool:
            answers = list(pool.map(save, range(400)))
    finally:
        stop.set()
        t.join(10)
    kinds = [(s, b["error"]["kind"] if s != 200 else "saved") for s, b in answers]
    saved = sum(k == "saved" for _s, k in kinds)
    print(f"\n400 saves during {swaps[0]} swaps: {saved} saved, "
          f"{400 - saved} refused ({sorted(set(kinds))})")
    # refused: a link on the way (400), or the folder gone at that instant (404)
    assert set(kinds) <= {(200, "saved"), (400, "OutsideFolder"), (404, "NotFound")}, \
        set(kinds)
    assert saved > 0
    assert _everything(outside) == []                     # nothing outside
    inside = _everything(srv.root)
    assert [f for f in inside if ".part" in f] == []      # no stray temporary
    landed = [f for f in inside if f.endswith(".yaml")]
    assert landed
    for f in landed:                                      # what landed is whole
        assert (srv.root / f).read_text().startswith("name: tiny"), f


def test_load_listing_and_save_follow_no_link_out(editor_server, tmp_path_factory):
    srv = editor_server
    outside = tmp_path_factory.mktemp("secret")
    (outside / "secret.yaml").write_text("name: secret\n")
    os.symlink(outside, srv.root / "door")                 # a folder link out
    os.symlink(outside / "secret.yaml", srv.root / "s.yaml")   # a file link out
    (srv.root / "mine.yaml").write_text("name: mine\n")
    status, files = srv.get("files")
    assert status == 200
    assert [f["path"] for f in files["files"]] == ["mine.yaml"]
    for path in ("door/secret.yaml", "s.yaml"):
        status, body = srv.post("load", {"path": path})
        assert status == 400 and body["error"]["kind"] == "OutsideFolder", body
        assert "secret" not in str(body).replace(path, "")
        status, body = srv.post("save", {"path": path, "document": DOC, "draft": True})
        assert status == 400 and body["error"]["kind"] == "OutsideFolder", body
    assert (outside / "secret.yaml").read_text() == "name: secret\n"
    assert _everything(outside) == ["secret.yaml"]
    assert os.path.islink(srv.root / "s.yaml")           # the link itself untouched


@pytest.mark.parametrize("path, kind", [
    ("a\x00b.yaml", "BadPath"),
    ("x" * 300 + ".yaml", "BadPath"),
    ("a/" * 2000 + "x.yaml", "BadPath"),
    ("a/" * 40 + "x.yaml", "BadPath"),
    ("../x.yaml", "OutsideFolder"),
    ("sub/../../x.yaml", "OutsideFolder"),
    ("/etc/x.yaml", "OutsideFolder"),
    ("\ud800.yaml", "BadPath"),
    ("", "BadPath"),
    (".", "BadPath"),
])
def test_a_bad_path_is_a_json_400_and_creates_nothing(editor_server, path, kind):
    """Before: a NUL, a 300-character name and a 2,000-folder path were 500s."""
    srv = editor_server
    for op, body in (("save", {"path": path, "document": DOC, "draft": True}),
                     ("load", {"path": path}),
                     ("validate", {"document": DOC, "path": path}),
                     ("save", {"path": "ok.yaml", "document": DOC, "draft": True,
                               "origin": path})):
        status, answer = srv.post(op, body)
        if op == "validate":               # the path only names where files resolve
            assert status == 200, answer
            continue
        if op == "save" and "origin" in body:
            if path == ".":                # names no file: nothing to keep forms from
                assert status == 200, answer
                continue
            assert status == 400, answer
            assert answer["error"]["kind"] == kind, answer
        else:
            assert status == 400, (op, answer)
            assert answer["error"]["kind"] == kind, answer
    assert [f for f in _everything(srv.root) if f != "ok.yaml"] == []


def test_loading_a_builtin_by_a_mapping_is_a_400(editor_server):
    status, body = editor_server.post("load", {"builtin": {"x": 1}})
    assert status == 400 and body["error"]["kind"] == "BadRequest", body
    assert "builtin" in body["error"]["message"]


def test_run_folders_are_under_the_editor_folder_and_go_with_their_runs(editor_server):
    from avblocks.editor.runs import MAX_RUNS
    srv = editor_server
    ids = []
    for _ in range(MAX_RUNS + 1):
        status, body = srv.post("run", {"document": DOC})
        assert status == 200, body
        ids.append(body["run"])
        t_end = time.monotonic() + 60
        while srv.get(f"run/{ids[-1]}")[1]["status"] == "running":
            assert time.monotonic() < t_end
            time.sleep(0.05)
    runs = srv.root / "avblocks-out"
    session, = runs.iterdir()
    assert session.name.startswith(".editor-")
    # the oldest run was dropped with its folder; the others keep their figures
    assert sorted(p.name for p in session.iterdir()) == sorted(ids[1:])
    assert srv.get(f"run/{ids[0]}")[0] == 404
    st = srv.get(f"run/{ids[-1]}")[1]
    assert st["figures"], st
    status, png = srv.request("GET", None, url=srv.url + st["figures"][0]["url"])
    assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n"
    assert (session / ids[-1] / "figures" / st["figures"][0]["name"]).read_bytes() == png
    srv.server.stop()
    assert list(srv.root.iterdir()) == []      # avblocks-out was the editor's: gone


def test_a_figure_swapped_for_a_link_is_not_served(editor_server, tmp_path_factory):
    srv = editor_server
    outside = tmp_path_factory.mktemp("elsewhere")
    (outside / "secret.png").write_bytes(b"\x89PNG\r\n\x1a\nsecret")
    status, body = srv.post("run", {"document": DOC})
    rid = body["run"]
    while srv.get(f"run/{rid}")[1]["status"] == "running":
        time.sleep(0.05)
    st = srv.get(f"run/{rid}")[1]
    name = st["figures"][0]["name"]
    figures = next((srv.root / "avblocks-out").iterdir()) / rid / "figures"
    os.unlink(figures / name)
    os.symlink(outside / "secret.png", figures / name)
    status, body = srv.request("GET", None, url=srv.url + st["figures"][0]["url"])
    assert status == 404 and b"secret" not in str(body).encode()
