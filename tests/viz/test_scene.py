"""Pixels of rendered 2D frames (headless Agg)."""

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

import avblocks as av
import avblocks.viz as viz
from avblocks.viz.shapes import DRAWINGS

RED = (255, 0, 0)
WHITE = (255, 255, 255)
EXT = (-2.0, 2.0, -2.0, 2.0)


def is_color(px, rgb, tol=30):
    return bool(np.all(np.abs(np.asarray(px[:3], int) - np.asarray(rgb, int)) <= tol))


def scene(n=1, **kw):
    kw.setdefault("extent", EXT)
    kw.setdefault("timestamp", False)
    kw.setdefault("figsize", (4, 4))
    return viz.Scene2D(n, **kw)


def red_run(img, s, x, y, axis, half=0.45, step=0.01):
    """Number of red pixels along a short line through (x, y) across the
    heading (axis=0: vertical line, axis=1: horizontal)."""
    count = 0
    for d in np.arange(-half, half, step):
        px, py = (x, y + d) if axis == 0 else (x + d, y)
        r, c = s.pixel(px, py)
        count += is_color(img[r, c], RED)
    return count


@pytest.mark.parametrize("theta", [0.0, np.pi / 2, np.pi, -2.0])
def test_agent_colour_position_and_heading(theta):
    s = scene(drawing="unicycle", size=1.0, color="red")
    pose = np.array([[0.3, -0.2, theta]])
    s.update(0.0, pose)
    img = s.render()
    c, sn = np.cos(theta), np.sin(theta)
    at = lambda f: s.pixel(0.3 + f * c, -0.2 + f * sn)  # noqa: E731 - along heading
    assert is_color(img[at(0.0)], RED)
    assert is_color(img[at(0.4)], RED)          # just behind the nose
    assert is_color(img[at(-0.45)], RED)        # near the wide base
    assert is_color(img[at(0.6)], WHITE)        # past the nose
    assert is_color(img[at(-0.6)], WHITE)       # past the base
    # the triangle is narrow ahead and wide behind: count red pixels across
    def width(f):
        n = 0
        for w in np.linspace(-0.4, 0.4, 81):
            r, col = s.pixel(0.3 + f * c - w * sn, -0.2 + f * sn + w * c)
            n += is_color(img[r, col], RED)
        return n
    assert width(-0.35) > 3 * width(0.35) > 0


def test_obstacle_fills_its_pixels():
    sq = Polygon([(1, 1), (1.8, 1), (1.8, 1.8), (1, 1.8)])
    tri = np.array([[-1.8, -1.8], [-1.0, -1.8], [-1.4, -1.0]])
    s = scene(obstacles=[sq, tri, Point(-1.5, 1.5).buffer(0.3)])
    s.update(0.0, np.array([[0.0, 0.0, 0.0]]))
    img = s.render()
    grey = (115, 115, 115)
    for p in [(1.4, 1.4), (1.1, 1.7), (-1.4, -1.6), (-1.5, 1.5)]:
        assert is_color(img[s.pixel(*p)], grey, tol=12), p
    for p in [(0.9, 1.4), (1.9, 1.4), (1.4, 1.9), (-1.1, -1.1), (-1.5, 1.9)]:
        assert is_color(img[s.pixel(*p)], WHITE), p


def test_obstacles_from_world_object_and_holes():
    class World:
        obstacles = [Polygon([(0, 0), (1.5, 0), (1.5, 1.5), (0, 1.5)],
                             [[(0.5, 0.5), (1, 0.5), (1, 1), (0.5, 1)]])]
    s = scene(obstacles=World())
    s.update(0.0, np.array([[-1.5, -1.5, 0.0]]))
    img = s.render()
    assert is_color(img[s.pixel(0.25, 0.25)], (115, 115, 115), tol=12)
    assert is_color(img[s.pixel(0.75, 0.75)], WHITE)      # the hole


def test_background_under_agents():
    bg = np.zeros((10, 10, 3), np.uint8)
    bg[:5] = (0, 200, 0)        # top rows: green (large y)
    bg[5:] = (0, 0, 255)        # bottom rows: blue
    s = scene(background=bg, background_extent=(-2, 0, -2, 0), drawing="robot",
              size=0.6, color="red")
    s.update(0.0, np.array([[-1.0, -1.5, 0.0]]))
    img = s.render()
    assert is_color(img[s.pixel(-1.0, -1.35)], RED)             # agent on top
    assert is_color(img[s.pixel(-0.5, -1.5)], (0, 0, 255))       # blue below
    assert is_color(img[s.pixel(-1.5, -0.3)], (0, 200, 0))       # green on top rows
    assert is_color(img[s.pixel(1.0, 1.0)], WHITE)               # outside the image


def test_colour_by_signal_and_collision_ring():
    s = scene(3, drawing="robot", size=0.5)
    pose = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    s.update(0.0, pose, color=np.array([False, True, False]),
             collision=np.array([False, False, True]))
    img = s.render()
    assert is_color(img[s.pixel(-1.0, 0.1)], (153, 153, 153))     # not informed: grey
    assert is_color(img[s.pixel(0.0, 0.1)], (214, 39, 40))        # informed: tab:red
    ring = 1.15 * 0.5 * 0.5
    hits = [is_color(img[s.pixel(1.0 + ring * np.cos(a), ring * np.sin(a))], RED, 60)
            for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)]
    assert sum(hits) >= 9
    assert not is_color(img[s.pixel(-1.0 + ring, 0.0)], RED, 60)
    # float values through the colormap
    s.clim = (0.0, 1.0)
    cols = s.colors(np.array([0.0, 0.5, 1.0]))
    assert np.allclose(cols, s.cmap([0.0, 0.5, 1.0]))


def test_trails_drawn_behind():
    s = scene(drawing="unicycle", size=0.3, color="blue")
    trail = np.stack([np.c_[np.linspace(-1.8, 0, 10), np.zeros(10)]], axis=1)
    s.update(0.0, np.array([[0.0, 0.0, 0.0]]), trails=trail)
    img = s.render()
    px = img[s.pixel(-1.0, 0.0)]
    assert px[2] > 200 and px[0] < 200        # faded blue line


def test_one_collection_per_group_at_1000_agents():
    n = 1000
    groups = [viz.Group(slice(0, 500), "car"), viz.Group(slice(500, n), "quadrotor")]
    s = scene(n, groups=groups, extent=(-50, 50, -50, 50))
    before = len(s.ax.collections)
    rng = np.random.default_rng(0)
    pose = np.c_[rng.uniform(-50, 50, (n, 2)), rng.uniform(-3, 3, n)]
    trails = pose[None, :, :2] + np.linspace(-1, 0, 5)[:, None, None]
    s.update(1.0, pose, trails=trails, steer=np.full(n, 0.3))
    s.render()
    assert len(s.ax.collections) == before
    assert len(s.groups[0]["poly"].get_paths()) == 500 * DRAWINGS["car"].n_parts
    assert len(s.groups[1]["trail"].get_segments()) == 500


def test_car_front_wheels_follow_steering():
    car = DRAWINGS["car"]
    v = car.place(np.array([[0.0, 0.0, 0.0]]), 1.0, steer=np.array([0.5]))
    for part in np.flatnonzero(car.steer):
        w = v[part]
        long_edge = w[1] - w[0]
        assert np.isclose(np.arctan2(long_edge[1], long_edge[0]), 0.5)
    fixed = np.flatnonzero(~car.steer)[1]
    assert np.allclose(v[fixed], car.parts[fixed])


def test_user_drawings():
    # body-frame vertices from a function of no arguments
    s = scene(drawing=lambda: [[0.5, 0.0], [-0.5, 0.5], [-0.5, -0.5]], size=1.0,
              color="red")
    s.update(0.0, np.array([[0.0, 0.0, np.pi]]))
    img = s.render()
    assert is_color(img[s.pixel(0.4, 0.0)], RED)
    assert is_color(img[s.pixel(-0.45, 0.0)], RED)
    assert is_color(img[s.pixel(-0.45, 0.4)], WHITE)    # narrow nose points to -x
    # a callable of poses returning world vertices
    def squares(p):
        off = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
        return p[:, None, :2] + off[None]
    s2 = scene(2, drawing=squares, color="blue")
    s2.update(0.0, np.array([[1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]))
    img = s2.render()
    assert is_color(img[s2.pixel(1.0, 1.0)], (0, 0, 255))
    assert is_color(img[s2.pixel(-1.0, 1.0)], (0, 0, 255))


def test_follow_camera():
    s = scene(2, follow=1, follow_width=2.0)
    s.update(0.0, np.array([[0.0, 0.0, 0.0], [10.0, 5.0, 0.0]]))
    assert np.allclose(s.ax.get_xlim(), (9.0, 11.0))
    assert np.allclose(s.ax.get_ylim(), (4.0, 6.0))


def test_bad_inputs_raise_in_words():
    with pytest.raises(av.ParameterError, match="unknown drawing"):
        scene(drawing="submarine")
    s = scene(2)
    with pytest.raises(av.ParameterError, match="pose has the wrong shape"):
        s.update(0.0, np.zeros((3, 3)))
