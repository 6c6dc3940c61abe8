"""TargetDetection: hand-built detection, nearest target, latched found, pickup."""

import numpy as np
import pytest

import avblocks as av
from avblocks.environment import TargetDetection, detect_targets


def test_detect_nearest_and_radii():
    pos = np.array([[0.0, 0], [5, 5], [10, 0]])
    tg = np.array([[1.0, 0], [0, 0.5], [10, 2.5], [50, 50]])
    best, seen = detect_targets(pos, tg, 1.0, [0.0, 0.0, 0.5, 0.0])
    assert best.tolist() == [1, -1, -1]  # 0.5 away beats 1.0 away
    assert seen.tolist() == [True, True, False, False]
    best, seen = detect_targets(pos, tg, [1.0, 1.0, 2.0], [0.0, 0.0, 0.5, 0.0])
    assert best.tolist() == [1, -1, 2]  # 2.5 <= 2.0 + 0.5 (touching)


def test_block_latched_found_and_pickup():
    tg = [[2.0, 0.0], [4.0, 0.0]]
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=[[0.0, 0.0, 0.0]]), name="f")
    c = d.add(av.blocks.Constant([[1.0, 0.0]]), name="c")
    d.connect(c.y, f.cmd)
    td = d.add(TargetDetection(1, tg, sensing_radius=0.55, period=0.1), name="td")
    d.connect(f.pose, td.pose)
    res = av.simulate(d, 5.0, dt=0.1, log=[td.detected, td.target, td.found])
    t = res.t
    det = res[td.detected][:, 0]
    np.testing.assert_array_equal(det, (np.abs(t - 2) <= 0.55) | (np.abs(t - 4) <= 0.55))
    tgt = res[td.target][:, 0]
    assert set(tgt[det].tolist()) == {0, 1} and np.all(tgt[~det] == -1)
    found = res[td.found]
    assert found.shape == (51, 2)
    k0 = int(np.argmax(found[:, 0]))
    assert t[k0] == pytest.approx(1.5) and found[k0:, 0].all()  # latched
    assert found[-1].tolist() == [True, True]
    # pickup: a found target disappears for everyone after its step
    b = TargetDetection(2, [[0.0, 0.0]], sensing_radius=1.0, pickup=True,
                        input="position")
    u = {"position": np.array([[0.5, 0.0], [-0.5, 0.0]])}
    x = b.initial_state()
    assert b.output(0.0, x, u, np)["detected"].tolist() == [True, True]
    x = {**x, **b.update(0.0, x, u, np)}
    y = b.output(0.1, x, u, np)
    assert y["detected"].tolist() == [False, False] and y["found"].tolist() == [True]


def test_errors():
    with pytest.raises(av.ParameterError):
        TargetDetection(2, [1.0, 2.0], sensing_radius=1.0)
    with pytest.raises(av.ParameterError):
        TargetDetection(2, [[1.0, 2.0]], sensing_radius=[1.0, 2.0, 3.0])


def _brute(pos, tg, R, r, active=None):
    D = np.hypot(*(pos[:, None, :] - tg[None, :, :]).transpose(2, 0, 1))
    ok = D <= np.broadcast_to(R, len(pos))[:, None] + np.broadcast_to(r, len(tg))[None]
    if active is not None:
        ok &= active[None]
    best = np.full(len(pos), -1)
    for i in range(len(pos)):
        js = np.flatnonzero(ok[i])
        if len(js):
            best[i] = js[np.lexsort((js, D[i, js]))[0]]
    return best, ok.any(axis=0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_detection_equals_brute_force(seed):
    gen = np.random.default_rng(seed)
    n, m = 120, 80
    pos = gen.uniform(0, 10, (n, 2))
    tg_dup = [[5.0, 5.0]] * 2           # duplicate targets
    tg = np.vstack([gen.uniform(0, 10, (m - 4, 2)), pos[:2] + [0.7, 0.0], tg_dup])
    R = gen.uniform(0.2, 0.9, n)
    r = gen.uniform(0.0, 0.3, m)
    r[-4:-2] = 0.0
    R[:2] = 0.7                        # exactly touching
    active = gen.uniform(size=m) < 0.8
    for act in (None, active):
        want = _brute(pos, tg, R, r, act)
        got = detect_targets(pos, tg, R, r, act)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    assert np.sum(want[0] >= 0) > 10 and 0 < want[1].sum() < m
    assert len(tg_dup) == 2


def test_compiled_engine_equals_numpy_and_brute_force():
    gen = np.random.default_rng(3)
    n, m = 30, 60
    tg = gen.uniform(0, 8, (m, 2))
    pose0 = np.column_stack([gen.uniform(0, 8, (n, 2)), gen.uniform(-np.pi, np.pi, n)])
    cmd = np.column_stack([gen.uniform(0.3, 1.0, n), gen.uniform(-0.4, 0.4, n)])

    def build():
        d = av.Diagram()
        veh = d.add(av.vehicles.Unicycle(pose0=pose0), name="veh")
        c = d.add(av.blocks.Constant(cmd), name="c")
        d.connect(c.y, veh.cmd)
        td = d.add(TargetDetection(n, tg, sensing_radius=0.6, target_radius=0.1,
                                   pickup=True), name="td")
        d.connect(veh.pose, td.pose)
        return d
    kw = dict(t_final=3.0, dt=0.05, log=["td.detected", "td.target", "td.found",
                                         "veh.pose"])
    ref = av.simulate(build(), **kw)
    got = av.simulate(build(), backend="jax", **kw)
    for k in ("td.detected", "td.target", "td.found"):
        np.testing.assert_array_equal(got[k], ref[k], err_msg=k)
    # and the NumPy run is the brute-force truth, step by step (pickup latched)
    found = np.zeros(m, bool)
    for s in range(len(ref.t)):
        best, seen = _brute(ref["veh.pose"][s, :, :2], tg, 0.6, 0.1, ~found)
        np.testing.assert_array_equal(ref["td.target"][s], best)
        np.testing.assert_array_equal(ref["td.found"][s], found | seen)
        found |= seen
    assert 5 < found.sum() < m
