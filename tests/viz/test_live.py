"""The live view in a real headless browser (Debian chromium + chromedriver
through selenium): page loads, agents are drawn where the camera geometry
says, pause stops simulated time, single step advances it by one step, a
slider changes a gain (seen in meta['param_changes'] and in the
trajectory), a wrong token is refused, closing the page ends the run with
results. Without a browser these skip locally and fail in CI."""

from __future__ import annotations

import asyncio
import math
import os
import re
import shutil
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

import avblocks as av
from avblocks.core.block import Block

viser = pytest.importorskip("viser") if not os.environ.get("CI") else __import__("viser")

from avblocks.environment import World  # noqa: E402
from avblocks.viz.live import LiveView  # noqa: E402

DT = 0.02
K0, K1 = 0.5, 4.0
P0 = np.array([[2.0, 1.0], [-6.0, -4.0]])      # agent 0 (red) never moves
BOUNDS = (-10.0, -10.0, 10.0, 10.0)


class BoundedGain(Block):
    """y = k u with k in [0, 4] (a slider in the page)."""

    def __init__(self, n):
        super().__init__()
        self.declare_parameter("k", K0, bounds=(0.0, K1), doc="gain")
        self.declare_input("u", (n, 2))
        self.declare_output("y", (n, 2))

    def output(self, t, x, u, xp):
        return {"y": self.k * u["u"]}


def make_diagram():
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[0.0, 0.0], [1.0, 0.0]]), name="c")
    g = d.add(BoundedGain(2), name="gain")
    fleet = d.add(av.vehicles.SingleIntegrator(P0), name="fleet")
    d.connect(c.y, g.u)
    d.connect(g.y, fleet.velocity)
    return d


def _browser():
    chrome = next((shutil.which(n) for n in ("chromium", "chromium-browser",
                                             "google-chrome") if shutil.which(n)), None)
    driver = shutil.which("chromedriver")
    if chrome is None or driver is None:
        msg = ("no headless browser: install Debian's chromium and chromium-driver "
               "(.ci/apt/live.txt)")
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("selenium is not installed (pip install 'avblocks[test]')")
    opts = Options()
    opts.binary_location = chrome
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
              "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
              "--window-size=1200,800", "--hide-scrollbars",
              # a headless page counts as hidden: do not throttle its frames
              "--disable-background-timer-throttling", "--disable-renderer-backgrounding",
              "--disable-backgrounding-occluded-windows"):
        opts.add_argument(a)
    return webdriver.Chrome(options=opts, service=Service(driver))


@pytest.fixture(scope="module")
def browser():
    drv = _browser()
    yield drv
    drv.quit()


def _wait(cond, timeout=15.0, every=0.1):
    t_end = time.monotonic() + timeout
    from selenium.common.exceptions import WebDriverException
    while time.monotonic() < t_end:
        try:
            v = cond()
        except WebDriverException:      # element not there (yet) or re-rendered
            v = None
        if v:
            return v
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout} s waiting for {cond}")


def _page_time(drv):
    m = re.search(r"t = ([0-9.]+) s", drv.find_element("tag name", "body").text)
    return float(m.group(1)) if m else None


def _button(drv, text):
    return drv.find_element("xpath", f"//button[normalize-space(.)='{text}']")


def _control(drv, label, what="input[not(@type='hidden')]"):
    return drv.find_element(
        "xpath", f"//label[normalize-space(.)='{label}']/ancestor::div"
                 f"[contains(@class,'mantine-Flex-root')][1]//{what}")


def _red_pixels(img, cx, cy, r):
    box = img[cy - r: cy + r + 1, cx - r: cx + r + 1].astype(int)
    red = (box[..., 0] > 120) & (box[..., 0] > 2 * box[..., 1]) & \
        (box[..., 0] > 2 * box[..., 2])
    return int(red.sum())


def _blue_pixels(img, cx, cy, r):
    box = img[cy - r: cy + r + 1, cx - r: cx + r + 1].astype(int)
    blue = (box[..., 2] > 120) & (box[..., 2] > 2 * box[..., 0]) & \
        (box[..., 2] > 1.5 * box[..., 1])
    return int(blue.sum())


def _screenshot(drv):
    import io

    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(drv.get_screenshot_as_png())).convert("RGB"))
    canvas = max(drv.find_elements("tag name", "canvas"),
                 key=lambda e: e.rect["width"] * e.rect["height"])
    return img, canvas.rect


def _pixel(rect, x, y, ratio=1.0):
    """Where the top camera puts world (x, y): it frames the world's bounds
    plus the view's 8 % (>= 1 m) margin in the canvas height, centred."""
    half = (BOUNDS[3] - BOUNDS[1]) / 2 + max(1.0, 0.08 * (BOUNDS[2] - BOUNDS[0]))
    s = rect["height"] / 2 / half
    cx = rect["x"] + rect["width"] / 2 + x * s
    cy = rect["y"] + rect["height"] / 2 - y * s
    return int(round(cx * ratio)), int(round(cy * ratio))


@pytest.mark.live
def test_live_page_in_browser(browser):
    drv = browser
    view = LiveView(make_diagram(), t_final=120.0, dt=DT, realtime=1.0,
                    colors=["red", "blue"], agent_size=1.0, trail=0.0,
                    obstacles=World([], bounds=BOUNDS), close_grace=1.0, verbose=False)
    view.start()
    try:
        assert view.url.startswith("http://127.0.0.1:")
        token = view.url.rstrip("/").rsplit("/", 1)[1]
        assert len(token) >= 32

        # -- wrong tokens are refused over HTTP and on the websocket
        port = view.port
        for bad in ("/", f"/{token[:-1]}x/", "/index.html", f"/x{token}/"):
            with pytest.raises(urllib.error.HTTPError) as ei:
                urllib.request.urlopen(f"http://127.0.0.1:{port}{bad}", timeout=5)
            assert ei.value.code == 403
        assert urllib.request.urlopen(view.url, timeout=5).status == 200
        assert _ws_status(port, "/not-the-token") == 403
        assert _ws_status(port, f"/{token}") == "open"

        # -- the page loads (in its own tab) and shows the run going
        first_tab = drv.current_window_handle
        drv.switch_to.new_window("tab")
        drv.get(view.url)
        t_a = _wait(lambda: _page_time(drv))
        _wait(lambda: len(view.server.get_clients()) == 1)
        _wait(lambda: (_page_time(drv) or 0) > t_a + 0.3)

        # -- pause: simulated time stops, in the page and in the simulator
        _button(drv, "Pause").click()
        _wait(lambda: _button(drv, "Resume"))
        time.sleep(0.3)
        k_paused = view.sim.k
        t_page = _page_time(drv)
        time.sleep(1.0)
        assert view.sim.k == k_paused
        assert _page_time(drv) == t_page
        assert abs(t_page - k_paused * DT) < 1e-6

        # -- single step: exactly one major step
        _button(drv, "Step").click()
        _wait(lambda: view.sim.k == k_paused + 1, timeout=5)
        time.sleep(0.5)
        assert view.sim.k == k_paused + 1
        k_paused += 1

        # -- agents drawn where the top camera geometry puts them
        x1 = float(view.sim.value("fleet.position")[1, 0])
        time.sleep(0.5)
        img, rect = _screenshot(drv)
        ratio = img.shape[1] / drv.execute_script("return window.innerWidth")
        rx, ry = _pixel(rect, *P0[0], ratio)
        assert _red_pixels(img, rx, ry, 6) >= 15, "red agent not at its place"
        mx, my = _pixel(rect, -P0[0, 0], -P0[0, 1], ratio)       # mirror: nothing
        assert _red_pixels(img, mx, my, 10) == 0
        bx, by = _pixel(rect, x1, P0[1, 1], ratio)
        assert _blue_pixels(img, bx, by, 6) >= 15, "blue agent not at its place"
        assert _red_pixels(img, bx, by, 6) == 0

        # -- move the gain slider to its end (keyboard on the thumb)
        from selenium.webdriver.common.keys import Keys
        thumb = _control(drv, "gain.k", "*[@role='slider']")
        drv.execute_script("arguments[0].focus();", thumb)   # a click would move it
        thumb.send_keys(Keys.END)
        _wait(lambda: view.sim._pending or float(view.sim.get_param("gain.k")) == K1,
              timeout=5)
        t_change = view.sim.t
        _button(drv, "Resume").click()
        _wait(lambda: view.sim.k > k_paused + 25, timeout=10)

        # -- closing the page ends the run, results saved
        drv.close()
        drv.switch_to.window(first_tab)
        res = view.wait(timeout=15)
        assert res is not None, "closing the page did not end the run"
    finally:
        if view.wait(timeout=0) is None:
            view.close()
    assert res.meta["live"]["ended_by"] == "page closed"
    assert res.meta["interrupted"] is True
    changes = res.meta["param_changes"]
    assert [(p, v) for _, p, v in changes] == [("gain.k", K1)]
    assert changes[0][0] == pytest.approx(t_change)
    # the trajectory: agent 1 moved K0 m/s before the change and K1 after
    X = res["fleet.position"]
    t = res.t
    v = np.diff(X[:, 1, 0]) / np.diff(t)
    before = t[1:] <= t_change + 1e-9
    after = t[:-1] >= t_change - 1e-9
    np.testing.assert_allclose(v[before], K0, rtol=1e-9)
    np.testing.assert_allclose(v[after], K1, rtol=1e-9)
    np.testing.assert_allclose(X[:, 0], np.broadcast_to(P0[0], X[:, 0].shape))
    assert res.t[-1] > t_change + 0.4
    # the diagram's own value is restored after the run
    assert float(view.compiled.get_param("gain.k")) == K0


def _ws_status(port, path):
    import websockets
    from websockets.exceptions import InvalidStatus

    async def go():
        try:
            async with websockets.connect(
                    f"ws://127.0.0.1:{port}{path}",
                    subprotocols=[f"viser-v{viser.__version__}"], open_timeout=5):
                return "open"
        except InvalidStatus as e:
            return e.response.status_code
    return asyncio.run(go())


def test_no_browser_never_blocks_and_paces():
    """With no page attached the run goes to t_final paced to the clock
    (x2 here: never earlier than half the simulated time) and returns."""
    view = LiveView(make_diagram(), t_final=1.0, dt=DT, realtime=2.0, verbose=False)
    t0 = time.perf_counter()
    res = view.run()
    wall = time.perf_counter() - t0
    assert res.meta["live"]["ended_by"] == "finished"
    assert res.t[-1] == pytest.approx(1.0)
    assert wall >= 0.5 - 0.02
    assert view.url in view._repr_html_()          # the notebook iframe
    np.testing.assert_allclose(res["fleet.position"][-1, 1], P0[1] + [K0 * 1.0, 0.0])


def test_simulate_live_flag_and_errors():
    """av.simulate(..., live=...) goes through the live view; bad input
    says what is wrong."""
    res = av.simulate(make_diagram(), 0.4, dt=DT,
                      live={"realtime": None, "verbose": False})
    assert res.meta["live"]["ended_by"] == "finished"
    assert len(res.t) == 21
    with pytest.raises(av.AvError, match="camera"):
        LiveView(make_diagram(), 1.0, camera="side", verbose=False)
    with pytest.raises(av.AvError, match="no such numeric parameter"):
        LiveView(make_diagram(), 1.0, params={"gain.q": 1.0}, verbose=False)
    with pytest.raises(av.AvError, match="trail_style must be 'dots' or 'lines'"):
        LiveView(make_diagram(), 1.0, trail_style="ribbons", verbose=False)
    assert math.isfinite(res.meta["wall_time"])


class EStopGate(Block):
    """y = (1 - estop) u: an emergency stop as a numeric parameter."""

    def __init__(self, n):
        super().__init__()
        self.declare_parameter("estop", 0.0, bounds=(0.0, 1.0), doc="1 stops")
        self.declare_input("u", (n, 2))
        self.declare_output("y", (n, 2))

    def output(self, t, x, u, xp):
        return {"y": (1.0 - self.estop) * u["u"]}


def test_stop_sets_estop_first_and_restart_takes_next_seed():
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0, 0.0], [0.0, 1.0]]), name="c")
    gate = d.add(EStopGate(2), name="gate")
    fleet = d.add(av.vehicles.SingleIntegrator(P0), name="fleet")
    d.connect(c.y, gate.u)
    d.connect(gate.y, fleet.velocity)
    # as fast as possible: t_final far enough that the run cannot end during the test
    view = LiveView(d, t_final=20000.0, dt=DT, realtime=None, verbose=False).start()
    try:
        _wait(lambda: view.sim.k > 20, timeout=10)
        view.restart()
        _wait(lambda: view.seed == 1 and view.sim.k > 10, timeout=10)
        view.pause()
        _wait(lambda: view._paused, timeout=5)
        k = view.sim.k
        view._cmds.put(("param", "gate.estop", 7.0))   # what the page sends: out of bounds
        view.stop()
        res = view.wait(timeout=10)
    finally:
        if view.wait(timeout=0) is None:
            view.close()
    live = res.meta["live"]
    assert live["ended_by"] == "stop button"
    assert [r["old_seed"] for r in live["restarts"]] == [0]
    assert res.meta["seed"] == 1
    # the log is the restarted run, from t0 on
    assert res.t[0] == 0.0 and np.allclose(np.diff(res.t), DT)
    # stop: estop set, one more step taken with it, then the end
    (t_stop, path, value), = res.meta["param_changes"]
    assert (path, value) == ("gate.estop", 1.0) and t_stop == pytest.approx(k * DT)
    assert res.meta["steps"] == k + 1
    X = res["fleet.position"]
    np.testing.assert_allclose(X[-1], X[-2])                      # stopped
    np.testing.assert_allclose(X[-2], P0 + np.eye(2) * (k * DT))
    assert float(view.compiled.get_param("gate.estop")) == 0.0    # restored


def test_cli_run_live_prints_url_and_saves(tmp_path, capsys):
    from avblocks.cli import main
    rc = main(["run", "formation", "--live", "--t-final", "0.4", "--realtime", "4",
               "--out", str(tmp_path), "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    url = re.search(r"avblocks live view: (http://127\.0\.0\.1:\d+/([\w-]+)/)", out)
    assert url and len(url.group(2)) >= 32
    res = av.Results.load(tmp_path / "results.nc")
    assert (tmp_path / "results.nc").is_file()
    assert res.t[-1] == pytest.approx(0.4)
