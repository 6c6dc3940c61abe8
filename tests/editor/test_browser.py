"""The editor in a real browser: the system Chromium driven by Playwright
against the real server (``editor_server``), as a user would use it.

Truth the page is checked against: the server's own answers computed
independently in Python (``validate`` of the same document gives the
library's error message the page must show on the port), the scenario files
on disk, and ``avblocks run`` of the saved file against the built-in
original (same ``summary.json``).

The screenshots of ``docs/editor.md`` are written here
(``docs/images/editor-*.png``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.editor]

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]
DOCS_IMAGES = Path(__file__).resolve().parents[2] / "docs" / "images"
STATIC = Path(__file__).resolve().parents[2] / "src" / "avblocks" / "editor" / "static"


def _need_browser():
    missing = []
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("playwright (pip)")
    if not Path(CHROMIUM).exists():
        missing.append(CHROMIUM)
    if not (STATIC / "index.html").is_file():
        missing.append("the built front end (editor/static)")
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"the browser tests need {missing} in CI")
        pytest.skip(f"needs {missing}")


@pytest.fixture(scope="module")
def browser():
    _need_browser()
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser, editor_server):
    ctx = browser.new_context(viewport={"width": 1440, "height": 880}, accept_downloads=True)
    pg = ctx.new_page()
    errors = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    # nothing may be loaded from outside the server
    outside = []
    pg.on("request", lambda r: outside.append(r.url) if not r.url.startswith(
        (editor_server.base, "data:", "blob:")) else None)
    pg.goto(editor_server.url)
    pg.wait_for_selector(".palette-item")
    yield pg
    ctx.close()
    assert not errors, errors
    assert not outside, outside


def shot(pg, name):
    DOCS_IMAGES.mkdir(parents=True, exist_ok=True)
    pg.wait_for_timeout(250)
    pg.screenshot(path=str(DOCS_IMAGES / f"editor-{name}.png"))


def wait_checked(pg):
    """Wait until the check shown is the answer about the document as it is now."""
    pg.wait_for_function("document.querySelector('[data-testid=check]')?.dataset.fresh === 'true'",
                         timeout=60_000)


def drag_from_palette(pg, type_, x, y):
    item = pg.locator(f'.palette-item[data-type="{type_}"]')
    item.scroll_into_view_if_needed()
    item.drag_to(pg.locator(".react-flow__pane"), target_position={"x": x, "y": y})


def handle(pg, block, port, side):
    kind = "source" if side == "out" else "target"
    return pg.locator(f'.react-flow__node[data-id="{block}"] '
                      f'.react-flow__handle.{kind}[data-handleid="{port}"]')


def wire(pg, src, dst):
    """Drag a wire from output ``src`` to input ``dst`` ("block.port") and wait
    for it on the canvas. A block that has just been added may not have its
    handles measured yet (React Flow measures them after the first paint): then
    the first drag misses, as a user's hurried one would, and is drawn again."""
    sb, sp = src.split(".")
    db, dp = dst.split(".")
    for _ in range(3):
        pg.wait_for_timeout(150)
        a = handle(pg, sb, sp, "out").bounding_box()
        b = handle(pg, db, dp, "in").bounding_box()
        pg.mouse.move(a["x"] + a["width"] / 2, a["y"] + a["height"] / 2)
        pg.mouse.down()
        pg.mouse.move((a["x"] + b["x"]) / 2, (a["y"] + b["y"]) / 2 + 20, steps=6)
        pg.mouse.move(b["x"] + b["width"] / 2, b["y"] + b["height"] / 2, steps=6)
        pg.mouse.up()
        if until(lambda: pg.locator(f'.react-flow__edge[data-id="{src}->{dst}"]').count() == 1,
                 timeout=3.0):
            return
    raise AssertionError(f"could not draw the wire {src} -> {dst}")


def wait_edge(pg, wire_id):
    """Wait for the wire ``"a.x->b.y"`` to be on the canvas."""
    pg.wait_for_selector(f'.react-flow__edge[data-id="{wire_id}"]', state="attached")


def click_empty(pg):
    """Click the canvas where nothing is drawn (clears the selection)."""
    box = pg.locator(".react-flow__pane").bounding_box()
    pg.locator(".react-flow__pane").click(position={"x": box["width"] / 2, "y": 20})


def until(check, timeout=10.0):
    """Poll ``check`` until it holds (the page re-renders asynchronously)."""
    t0 = time.monotonic()
    while True:
        ok = check()
        if ok or time.monotonic() - t0 > timeout:
            return ok
        time.sleep(0.05)


def show_everything(pg, n_blocks):
    """Zoom out (the zoom buttons) until all ``n_blocks`` blocks are drawn."""
    for _ in range(12):
        if pg.locator(".react-flow__node-block").count() >= n_blocks:
            break
        pg.locator(".react-flow__controls-zoomout").click()
        pg.wait_for_timeout(120)
    assert pg.locator(".react-flow__node-block").count() == n_blocks


def blocks_on_canvas(pg):
    return sorted(pg.eval_on_selector_all(".react-flow__node-block",
                                          "ns => ns.map(n => n.dataset.id)"))


def current_document(pg, editor_server, name):
    """The document as the page holds it, read back from a saved file."""
    pg.keyboard.press("Escape")
    pg.keyboard.press("Control+Shift+S")
    pg.get_by_label("File path").fill(name)
    pg.get_by_test_id("saveas-ok").click()
    pg.wait_for_selector(".modal", state="detached")
    path = editor_server.root / name
    for _ in range(50):
        if path.is_file():
            break
        time.sleep(0.1)
    status, loaded = editor_server.post("load", {"path": name})
    assert status == 200, loaded
    return loaded["document"]


def test_403_without_the_token(browser, editor_server):
    _need_browser()
    ctx = browser.new_context()
    pg = ctx.new_page()
    r = pg.goto(editor_server.base)
    assert r.status == 403
    r = pg.goto(editor_server.base + "api/palette")
    assert r.status == 403
    r = pg.goto(editor_server.base + "x" + editor_server.token + "/")
    assert r.status == 403
    r = pg.goto(editor_server.url)
    assert r.status == 200
    ctx.close()


def test_draw_wire_set_agents_run(page, editor_server):
    pg = page
    shot(pg, "empty")
    drag_from_palette(pg, "vehicles.Unicycle", 260, 260)
    drag_from_palette(pg, "controllers.PointToPoint", 620, 260)
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    assert blocks_on_canvas(pg) == ["point_to_point", "unicycle"]

    # both wires, each way
    wire(pg, "unicycle.pose", "point_to_point.pose")
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_edge(pg, "unicycle.pose->point_to_point.pose")
    wait_edge(pg, "point_to_point.cmd->unicycle.cmd")
    wait_checked(pg)

    # the diagram parameters: agents 15 -> 300 in one field
    click_empty(pg)
    agents = pg.get_by_test_id("dparam-agents")
    agents.fill("300")
    wait_checked(pg)

    doc = current_document(pg, editor_server, "drawn.yaml")
    assert doc["parameters"]["agents"] == 300
    assert sorted(map(tuple, doc["wires"])) == [("point_to_point.cmd", "unicycle.cmd"),
                                                ("unicycle.pose", "point_to_point.pose")]
    assert {b: v["type"] for b, v in doc["blocks"].items()} == {
        "unicycle": "vehicles.Unicycle", "point_to_point": "controllers.PointToPoint"}

    # the server's own check of what the page drew: it builds, and the wire
    # labels are the signal shapes it reports (300 agents)
    status, v = editor_server.post("validate", {"document": doc})
    assert status == 200 and v["ok"], v["errors"]
    assert pg.get_by_test_id("check").inner_text().startswith("✓")
    label = pg.locator('[data-wire="unicycle.pose->point_to_point.pose"]').inner_text()
    assert label == v["signals"]["unicycle.pose"]["shape"]
    assert "300" in label
    shot(pg, "wired")

    # run a short simulation in the page
    pg.get_by_label("t_final").fill("2")
    pg.get_by_test_id("run").click()
    outcome = pg.get_by_test_id("outcome")
    outcome.wait_for(timeout=120_000)
    assert outcome.inner_text().strip()
    pg.locator(".run-state.done").wait_for(timeout=120_000)
    # after the run, a click on a wire plots its signal
    pg.locator('[data-wire="unicycle.pose->point_to_point.pose"]').click()
    pg.get_by_test_id("signal-plot").wait_for(timeout=30_000)
    # (300, 3): one agent's x, y and heading
    assert pg.locator('[data-testid="signal-plot"] path').count() == 3
    shot(pg, "run")


def test_wrong_wire_shows_the_library_error_on_the_port(page, editor_server):
    pg = page
    drag_from_palette(pg, "vehicles.Unicycle", 260, 260)
    drag_from_palette(pg, "controllers.PointToPoint", 620, 260)
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    # a pose (N, 3) into the unicycle's command input (N, 2)
    wire(pg, "unicycle.pose", "unicycle.cmd")
    wait_edge(pg, "unicycle.pose->unicycle.cmd")
    wait_checked(pg)
    bad = pg.locator('.react-flow__node[data-id="unicycle"] '
                     '.react-flow__handle.target.bad[data-handleid="cmd"]')
    bad.wait_for()

    # what the library says about this diagram, asked independently
    doc = current_document(pg, editor_server, "wrong.yaml")
    status, v = editor_server.post("validate", {"document": doc})
    assert status == 200 and not v["ok"]
    on_port = [e["message"] for e in v["errors"]
               if e.get("block") == "unicycle" and e.get("port") == "cmd"]
    assert on_port, v["errors"]
    title = bad.get_attribute("title")
    for m in on_port:
        assert m in title
    # the Problems list shows it too, and a click selects the block
    pg.get_by_test_id("tab-problems").click()
    prob = pg.locator(".problem", has_text=on_port[0])
    prob.first.click()
    assert until(lambda: pg.locator('.react-flow__node[data-id="unicycle"].selected').count() == 1)
    pg.keyboard.press("f")  # fit the view
    pg.wait_for_timeout(400)
    shot(pg, "error")

    # one driver per input: a wire into the taken input replaces the old one
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_edge(pg, "point_to_point.cmd->unicycle.cmd")
    assert pg.locator('.react-flow__edge[data-id="unicycle.pose->unicycle.cmd"]').count() == 0
    assert "one driver" in pg.get_by_test_id("toast").last.inner_text()
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")


def test_undo_redo(page):
    pg = page
    drag_from_palette(pg, "vehicles.Unicycle", 260, 260)
    drag_from_palette(pg, "controllers.PointToPoint", 620, 260)
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    pg.wait_for_selector(".react-flow__edge", state="attached")
    click_empty(pg)
    pg.keyboard.press("Control+z")
    assert until(lambda: pg.locator(".react-flow__edge").count() == 0)
    pg.keyboard.press("Control+z")
    assert until(lambda: blocks_on_canvas(pg) == ["unicycle"])
    pg.keyboard.press("Control+Shift+z")
    assert until(lambda: blocks_on_canvas(pg) == ["point_to_point", "unicycle"])
    pg.keyboard.press("Control+y")
    assert until(lambda: pg.locator(".react-flow__edge").count() == 1)
    # the toolbar buttons do the same
    pg.get_by_test_id("undo").click()
    assert until(lambda: pg.locator(".react-flow__edge").count() == 0)
    pg.get_by_test_id("redo").click()
    assert until(lambda: pg.locator(".react-flow__edge").count() == 1)
    # copy / paste renames; delete removes; undo brings it back
    pg.locator('.react-flow__node[data-id="unicycle"]').click()
    pg.keyboard.press("Control+c")
    pg.keyboard.press("Control+v")
    pg.wait_for_selector('.react-flow__node[data-id="unicycle2"]')
    pg.keyboard.press("Delete")
    assert until(lambda: blocks_on_canvas(pg) == ["point_to_point", "unicycle"])
    pg.keyboard.press("Control+z")
    assert until(lambda: blocks_on_canvas(pg) == ["point_to_point", "unicycle", "unicycle2"])


def test_search_to_add_and_group(page):
    pg = page
    pg.keyboard.press("/")
    pg.keyboard.type("unicycle first")
    pg.keyboard.press("Enter")
    pg.wait_for_selector('.react-flow__node[data-id="unicycle"]')
    pg.keyboard.press("/")
    pg.keyboard.type("PointToPoint")
    pg.keyboard.press("Enter")
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_edge(pg, "point_to_point.cmd->unicycle.cmd")
    pg.locator('.react-flow__node[data-id="point_to_point"]').click()
    pg.keyboard.press("Control+g")
    g = pg.locator(".react-flow__node-subsystem")
    g.wait_for()
    # the group's ports are the wires it cuts
    assert sorted(g.locator(".react-flow__handle").evaluate_all(
        "hs => hs.map(h => h.dataset.handleid)")) == ["point_to_point.cmd", "point_to_point.pose"]
    pg.keyboard.press("f")
    pg.wait_for_timeout(400)
    shot(pg, "group")
    g.dblclick()
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    pg.wait_for_timeout(400)
    shot(pg, "group-inside")
    assert pg.locator('.react-flow__node[data-id="unicycle"]').count() == 0
    assert pg.locator(".breadcrumb button").count() == 2
    pg.keyboard.press("Escape")
    pg.keyboard.press("Escape")
    pg.wait_for_selector(".react-flow__node-subsystem")


def test_formation_load_save_run_same_summary(page, editor_server, tmp_path_factory):
    pg = page
    # the built-in case study, laid out by elk (it carries no positions)
    pg.get_by_role("button", name="Open").click()
    pg.locator('[data-builtin="formation"]').click()
    pg.wait_for_selector('.react-flow__node[data-id="supervisor"]')
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")
    # fitted at a readable zoom, it does not all fit at 1440 x 880: zoomed out, it is all there
    show_everything(pg, 6)
    assert blocks_on_canvas(pg) == ["collision", "drive", "fleet", "lf", "morph", "supervisor"]
    boxes = pg.eval_on_selector_all(
        ".react-flow__node-block",
        "ns => ns.map(n => { const r = n.getBoundingClientRect(); "
        "return [r.x, r.y, r.right, r.bottom]; })")
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]), (a, b)
    shot(pg, "formation")
    # a built-in has no file here: Ctrl+S asks for one, and the file keeps the built-in's comments
    pg.keyboard.press("Control+s")
    pg.get_by_label("File path").fill("from_builtin.yaml")
    pg.get_by_test_id("saveas-ok").click()
    pg.get_by_test_id("toast").filter(has_text="saved from_builtin.yaml").wait_for()
    assert "# the team is a leader and its followers" in (
        editor_server.root / "from_builtin.yaml").read_text()

    # the same file under the server's folder: open it, save it
    import avblocks.scenarios
    original = Path(avblocks.scenarios.__file__).parent / "formation.yaml"
    saved = editor_server.root / "formation.yaml"
    shutil.copy(original, saved)
    pg.get_by_role("button", name="Open").click()
    pg.locator('[data-file="formation.yaml"]').click()
    pg.wait_for_function("document.querySelector('[data-testid=file-title]').textContent.startsWith('formation.yaml')")
    pg.wait_for_selector('.react-flow__node[data-id="supervisor"]')
    pg.keyboard.press("Control+s")
    pg.get_by_test_id("toast").filter(has_text="saved formation.yaml").wait_for()
    text = saved.read_text()
    assert "# the team is a leader and its followers" in text  # comments kept
    assert "n: &n" in text and "*n" in text  # anchors kept
    assert "editor:" in text  # the layout under its own key

    # the saved file and the built-in run to the same summary
    out = tmp_path_factory.mktemp("runs")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    sums = []
    for target, name in [(str(saved), "saved"), ("formation", "builtin")]:
        subprocess.run([sys.executable, "-m", "avblocks", "run", target, "--quiet",
                        "--t-final", "4", "--out", str(out / name)],
                       check=True, env=env, cwd=out, timeout=600, stdout=subprocess.DEVNULL)
        s = json.loads((out / name / "summary.json").read_text())
        for k in ("realtime_factor", "wall_s", "files"):  # the clock and where it wrote
            s.pop(k)
        sums.append(s)
    assert sums[0] == sums[1]
    assert sums[0]["outcome"].startswith("wedge")

    # a file changed on disk since it was loaded: the page offers a choice
    saved.write_text(saved.read_text().replace("spacing: 1.5 ", "spacing: 1.6 "))
    click_empty(pg)
    pg.get_by_test_id("dparam-gain").fill("1.4")
    pg.keyboard.press("Control+s")
    pg.get_by_test_id("overwrite").click()
    pg.wait_for_selector(".modal", state="detached")
    pg.get_by_test_id("toast").filter(has_text="saved formation.yaml").last.wait_for()
    text = saved.read_text()
    assert "gain: 1.4" in text and "spacing: 1.5 " in text


def test_help_overlay_and_python_export(page, editor_server):
    pg = page
    pg.keyboard.press("?")
    dialog = pg.get_by_role("dialog", name="Keyboard shortcuts")
    dialog.wait_for()
    assert "Ctrl+G" in dialog.inner_text()
    pg.keyboard.press("Escape")
    dialog.wait_for(state="detached")
    # the palette's + button adds a block where there is room in view
    for t in ("vehicles.Unicycle", "controllers.PointToPoint"):
        item = pg.locator(f'.palette-item[data-type="{t}"]')
        item.scroll_into_view_if_needed()
        item.hover()
        item.locator(".pi-add").click()
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_checked(pg)
    # (saved first: a new diagram saved as exported.yaml is named after it)
    doc = current_document(pg, editor_server, "exported.yaml")
    assert doc["name"] == "exported"
    pg.get_by_label("Export").select_option("python")
    code = pg.locator("pre.code")
    code.wait_for()
    shown = code.inner_text()
    status, r = editor_server.post("export", {"document": doc, "format": "python"})
    assert status == 200
    assert shown.strip() == r["text"].strip()


TEAM_YAML = """\
# a team of {n}: a Unicycle fleet driven to random waypoints
name: team
parameters:
  agents: {n}
blocks:
  fleet:
    type: vehicles.Unicycle
    pose0: {{random_poses: {{n: $agents, area: [20, 20], seed: 3}}}}
  drive:
    type: controllers.PointToPoint
    n: $agents
    waypoints: {{random_waypoints: {{n: $agents, count: 2, area: [20, 20], seed: 4}}}}
wires:
  - [fleet.pose, drive.pose]
  - [drive.cmd, fleet.cmd]
simulation: {{t_final: 60, dt: 0.05}}
"""


def open_file(pg, editor_server, name, text):
    """Write a scenario file into the server's folder and open it in the page."""
    (editor_server.root / name).write_text(text)
    pg.get_by_role("button", name="Open").click()
    pg.locator(f'[data-file="{name}"]').click()
    pg.wait_for_function(f"document.querySelector('[data-testid=file-title]')"
                         f".textContent.startsWith('{name}')")
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")


def _export_download(pg, fmt):
    with pg.expect_download() as dl:
        pg.get_by_label("Export").select_option(fmt)
    d = dl.value
    return d.suggested_filename, Path(d.path()).read_bytes()


def test_export_svg_and_png_from_the_page(page, editor_server):
    import base64
    import io
    import xml.etree.ElementTree as ET

    import numpy as np
    from PIL import Image
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))

    # SVG: a well-formed SVG document naming every block of the diagram
    name, raw = _export_download(pg, "svg")
    assert name == "team.svg"
    root = ET.fromstring(raw)
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    texts = " ".join("".join(t.itertext()) for t in root.iter("{http://www.w3.org/2000/svg}text"))
    for block in ("fleet", "drive"):
        assert block in texts, (block, texts[:400])

    # PNG: decodes (Pillow) to the size of the server's own export of the same file, not blank
    name, raw = _export_download(pg, "png")
    assert name == "team.png"
    img = Image.open(io.BytesIO(raw))
    img.load()
    status, loaded = editor_server.post("load", {"path": "team.yaml"})
    status, ref = editor_server.post("export", {"document": loaded["document"], "format": "png"})
    assert status == 200, ref
    ref_img = Image.open(io.BytesIO(base64.b64decode(ref["data_url"].split(",", 1)[1])))
    assert img.size == ref_img.size and img.size[0] > 100 and img.size[1] > 100
    px = np.asarray(img.convert("RGB"), dtype=float)
    ink = (px.min(axis=2) < 200).mean()           # pixels that are not (near) white
    assert 0.005 < ink < 0.6, ink
    assert len(np.unique(px.reshape(-1, 3), axis=0)) > 8   # lines, text and fills, not one colour


def test_live_button_opens_the_drawn_diagram_in_the_live_view(page, editor_server):
    import re
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))
    with pg.context.expect_page(timeout=60_000) as popup:
        pg.get_by_role("button", name="Live").click()
    live = popup.value
    try:
        port = int(re.match(r"http://127\.0\.0\.1:(\d+)/", live.url).group(1))
        assert port != editor_server.server.port       # the live view's own server
        # its status line: the diagram's agent count, and simulated time going on
        live.wait_for_function("/\\bt = [0-9.]+ s/.test(document.body.innerText)",
                               timeout=90_000)
        text = live.locator("body").inner_text()
        assert re.search(r"\b7 agents\b", text), text

        def t_page():
            m = re.search(r"\bt = ([0-9.]+) s", live.locator("body").inner_text())
            return float(m.group(1)) if m else None

        t0 = t_page()
        assert until(lambda: (t_page() or 0) > t0 + 0.2, timeout=30), (t0, t_page())
    finally:
        live.close()


def _red_pixels(png, box, pad=4):
    import io

    import numpy as np
    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    x0, y0 = int(box["x"]) - pad, int(box["y"]) - pad
    x1, y1 = int(box["x"] + box["width"]) + pad, int(box["y"] + box["height"]) + pad
    sub = img[max(0, y0):y1, max(0, x0):x1]
    r, g, b = sub[..., 0], sub[..., 1], sub[..., 2]
    return int(((r > 180) & (r - g > 90) & (r - b > 90)).sum())


def test_a_block_with_an_error_stays_marked_zoomed_far_out(page, editor_server):
    """Zoomed out until ports are no longer drawn (a few hundred blocks in
    view), the block the check names is still red on the canvas and in the
    minimap; the block without an error is not."""
    pg = page
    text = TEAM_YAML.format(n=4).replace("  - [drive.cmd, fleet.cmd]\n", "")
    (editor_server.root / "half.yaml").write_text(text)
    pg.get_by_role("button", name="Open").click()
    pg.locator('[data-file="half.yaml"]').click()
    pg.wait_for_selector('.react-flow__node[data-id="fleet"]')
    wait_checked(pg)
    # the library's own verdict: fleet.cmd is not driven (and nothing about drive)
    status, loaded = editor_server.post("load", {"path": "half.yaml"})
    status, v = editor_server.post("validate", {"document": loaded["document"]})
    assert {e.get("block") for e in v["errors"]} == {"fleet"}, v["errors"]
    pane = pg.locator(".react-flow__pane").bounding_box()
    pg.mouse.move(pane["x"] + pane["width"] / 3, pane["y"] + pane["height"] / 3)
    for _ in range(40):
        if "tiny" in pg.locator(".canvas").get_attribute("class"):
            break
        pg.mouse.wheel(0, 240)
        pg.wait_for_timeout(60)
    assert "tiny" in pg.locator(".canvas").get_attribute("class")
    assert pg.locator(".react-flow__handle").first.is_hidden()      # ports not drawn
    pg.wait_for_timeout(300)
    png = pg.screenshot()
    fleet = pg.locator('.react-flow__node[data-id="fleet"]').bounding_box()
    drive = pg.locator('.react-flow__node[data-id="drive"]').bounding_box()
    assert fleet["width"] < 70                                        # really zoomed out
    assert _red_pixels(png, fleet) > 4 * fleet["width"], fleet
    assert _red_pixels(png, drive) == 0
    mini = pg.locator(".react-flow__minimap").bounding_box()
    assert _red_pixels(png, mini, pad=0) > 0
