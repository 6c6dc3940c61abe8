"""Case study IV.B complete: scouts search, a finder returns, the nest learns."""

import numpy as np

import avblocks as av
from avblocks.scenarios import honeybee as hb
from avblocks.scenarios.nest import hexagon_radius


def test_detection_return_and_full_propagation():
    # seed 4: events well inside 200 s with the core.rng Threefry stream (seed 1
    # finds the source at 126 s and is back at 158 s, too late for 100 bees)
    d, sim = hb.make_diagram(agents=100, t_final=200.0, log_every=1, seed=4)
    res = av.simulate(d, progress=False, **sim)
    m, R = 12, 3.0
    pose = np.asarray(res["bees.pose"])
    mode = np.asarray(res["modes.mode"])
    inf = np.asarray(res["gossip.informed"])[:, m:]
    src = np.array([-55.0, 18.0])
    gate = hb.entrance(hexagon_radius(100, 0.5))
    dist_src = np.linalg.norm(pose[:, :m, :2] - src, axis=2)          # (T, m)
    dist_gate = np.linalg.norm(pose[:, :m, :2] - gate, axis=2)
    tl = hb.timeline(res, m)
    print(f"\nsource detected at {tl['detected_s']:.1f} s, first scout back at "
          f"{tl['returned_s']:.1f} s, all 100 informed at {tl['all_informed_s']:.1f} s")
    # detection: every scout that left 'search' was within the sensing radius
    # at the step before it switched (the mode shows one step after the
    # detection), and none did so without it
    assert tl["detected_s"] is not None
    for i in range(m):
        k = np.flatnonzero(mode[:, i] >= 1)
        if k.size:
            assert dist_src[k[0] - 1, i] <= R + 1e-9, i
            assert np.all(dist_src[:k[0] - 1, i] > R), i
        else:
            assert np.all(dist_src[:, i] > R), i
    # return: a finder reached the entrance, and switched to 'nest' there
    assert tl["returned_s"] is not None and tl["returned_s"] > tl["detected_s"]
    for i in range(m):
        k = np.flatnonzero(mode[:, i] == 2)
        if k.size:
            assert dist_gate[k[0] - 1, i] <= 1.0 + 1e-9
            assert (mode[:k[0], i] == 1).any()          # came through 'return'
    # propagation: nobody in the nest knew before a scout was back, the
    # informed set only grows, and everyone knows by the end
    k_back = int(np.argmax((mode == 2).any(axis=1)))
    assert not inf[:k_back].any()
    assert np.all(inf[1:] >= inf[:-1])
    assert inf[-1].all() and tl["all_informed_s"] > tl["returned_s"]
    np.testing.assert_allclose(tl["fraction"], inf.mean(axis=1))
