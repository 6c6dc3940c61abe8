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
