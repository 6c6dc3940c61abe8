"""CommChannel and Gossip: loss statistics, exact latency, spread in
graph-diameter steps."""

import networkx as nx
import numpy as np
import pytest

import avblocks as av
from avblocks.environment import Broadcast, CommChannel, Gossip, gossip_step


def _static(d, pos, name="p"):
    return d.add(av.blocks.Constant(np.asarray(pos, float)), name=name)


def test_loss_fraction_within_binomial_bounds():
    n, p, steps = 10, 0.3, 400
    gen = np.random.default_rng(0)
    pos = gen.uniform(0, 1, (n, 2))
    d = av.Diagram()
    ps = _static(d, pos)
    msg = d.add(av.blocks.Constant(np.arange(n, dtype=float)[:, None] * 10), name="m")
    ch = d.add(CommChannel(n, radius=5.0, k=n - 1, p_loss=p, input="position"), name="ch")
    d.connect(ps.y, ch.position)
    d.connect(msg.y, ch.message)
    res = av.simulate(d, steps * 0.01, dt=0.01, log=[ch.sender, ch.received], seed=3)
    s = res[ch.sender][1:]  # sample 0 is the empty delay line
    trials = s.size
    frac = np.mean(s >= 0)
    sigma = np.sqrt(p * (1 - p) / trials)
    assert abs(frac - (1 - p)) <= 4 * sigma
    # each delivered payload is the sender's message; lost slots carry 0
    got = res[ch.received][1:, :, :, 0]
    np.testing.assert_array_equal(got, np.where(s >= 0, 10.0 * s, 0.0))
    # senders are distinct neighbours, never the receiver
    assert not np.any(s == np.arange(n)[None, :, None])
    # same seed, same run; another seed, another loss pattern
    again = av.simulate(d, steps * 0.01, dt=0.01, log=[ch.sender], seed=3)
    np.testing.assert_array_equal(again[ch.sender][1:], s)
    other = av.simulate(d, steps * 0.01, dt=0.01, log=[ch.sender], seed=4)
    assert np.any(other[ch.sender][1:] != s)


@pytest.mark.parametrize("latency", [0, 1, 3])
def test_latency_delays_by_exactly_k_steps(latency):
    n, dt = 3, 0.1
    d = av.Diagram()
    ps = _static(d, [[0, 0], [1, 0], [5, 0]])
    one = d.add(av.blocks.Constant(np.ones((n, 1))), name="one")
    clock = d.add(av.blocks.Integrator(np.zeros((n, 1))), name="clk")  # message = t
    d.connect(one.y, clock.u)
    ch = d.add(CommChannel(n, radius=1.5, k=2, latency=latency, input="position",
                           capacity=4), name="ch")
    d.connect(ps.y, ch.position)
    d.connect(clock.y, ch.message)
    res = av.simulate(d, 2.0, dt=dt, log=[ch.sender, ch.received])
    s, r, t = res[ch.sender], res[ch.received][..., 0], res.t
    # the compiled engine: the same delay line, sample for sample
    jr = av.simulate(d, 2.0, dt=dt, log=[ch.sender, ch.received], backend="jax")
    np.testing.assert_array_equal(jr[ch.sender], s)
    np.testing.assert_allclose(jr[ch.received], res[ch.received], atol=1e-12)
    L = latency
    assert np.all(s[:L] == -1)
    assert s[L:, 0].tolist() == [[1, -1]] * (len(t) - L)
    assert s[L:, 1].tolist() == [[0, -1]] * (len(t) - L)
    assert np.all(s[:, 2] == -1)  # out of range
    np.testing.assert_allclose(r[L:, 0, 0], t[:len(t) - L], atol=1e-12)
    np.testing.assert_allclose(r[L:, 1, 0], t[:len(t) - L], atol=1e-12)


def _connected_rgg(n, radius, seed):
    gen = np.random.default_rng(seed)
    while True:
        pos = gen.uniform(0, 1, (n, 2))
        D = np.hypot(*(pos[:, None] - pos[None]).transpose(2, 0, 1))
        g = nx.Graph()
        g.add_nodes_from(range(n))
        g.add_edges_from(zip(*np.nonzero(np.triu(D <= radius, 1))))
        if nx.is_connected(g):
            return pos, g


@pytest.mark.parametrize("seed", [0, 1])
def test_gossip_reaches_everyone_in_diameter_steps(seed):
    n, radius = 80, 0.22
    pos, g = _connected_rgg(n, radius, seed)
    diam = nx.diameter(g)
    src = nx.periphery(g)[0]  # a node whose eccentricity is the diameter
    hops = nx.single_source_shortest_path_length(g, src)
    d = av.Diagram()
    ps = _static(d, pos)
    flag = np.zeros(n, dtype=bool)
    flag[src] = True
    fl = d.add(av.blocks.Constant(flag), name="flag")
    gs = d.add(Gossip(n, radius=radius, input="position"), name="g")
    d.connect(ps.y, gs.position)
    d.connect(fl.y, gs.flag)
    res = av.simulate(d, (diam + 3) * 0.01, dt=0.01, log=[gs.informed])
    inf = res[gs.informed]
    first_all = int(np.argmax(inf.all(axis=1)))
    assert inf.all(axis=1).any() and first_all == diam
    # informed after k steps = nodes within k hops of the seed
    expect = [sum(1 for h in hops.values() if h <= k) for k in range(len(inf))]
    assert inf.sum(axis=1).tolist() == expect
    assert np.all(np.diff(inf.astype(int), axis=0) >= 0)  # latched


def test_gossip_with_loss_is_slower_and_still_complete():
    pos, g = _connected_rgg(60, 0.25, 2)
    seeds = np.zeros(60, bool)
    seeds[0] = True
    key = av.core.rng.key(0)
    inf, k_all = seeds.copy(), None
    for k in range(200):
        key, sub = av.core.rng.split(key)
        inf, _ = gossip_step(inf, pos, 0.25, 0.6, sub)
        if inf.all():
            k_all = k + 1
            break
    assert k_all is not None
    ecc = nx.eccentricity(g, 0)
    assert k_all >= ecc


def test_broadcast_carries_the_seed_value():
    pos = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0], [10, 0]])
    b = Broadcast(5, radius=1.0, value_dim=2, input="position")
    u = {"position": pos, "flag": np.array([False, False, False, True, False]),
         "value": np.tile([[7.0, -1.0]], (5, 1))}
    x = b.initial_state()
    for _ in range(4):
        x = {**x, **b.update(0.0, x, u, np)}
    y = b.output(0.0, x, {**u, "value": np.zeros((5, 2))}, np)
    assert y["informed"].tolist() == [True, True, True, True, False]
    np.testing.assert_array_equal(y["value"][:4], [[7.0, -1.0]] * 4)
    np.testing.assert_array_equal(y["value"][4], [0.0, 0.0])


def test_errors():
    with pytest.raises(av.ParameterError):
        CommChannel(3, radius=1.0, p_loss=1.5)
    with pytest.raises(av.ParameterError):
        CommChannel(3, radius=1.0, latency=-1)
    with pytest.raises(av.ParameterError):
        Gossip(3, radius=0.0)


# --------------------------------------------------- compiled == NumPy engine
def _moving_swarm(n, seed, capacity=None):
    gen = np.random.default_rng(seed)
    pose0 = np.column_stack([gen.uniform(0, 4, (n, 2)), gen.uniform(-np.pi, np.pi, n)])
    cmd = np.column_stack([gen.uniform(0.2, 1.0, n), gen.uniform(-0.5, 0.5, n)])
    d = av.Diagram()
    veh = d.add(av.vehicles.Unicycle(pose0=pose0), name="veh")
    c = d.add(av.blocks.Constant(cmd), name="cmd")
    d.connect(c.y, veh.cmd)
    ch = d.add(CommChannel(n, radius=1.0, k=5, msg_dim=2, p_loss=0.3, latency=2,
                           capacity=capacity), name="ch")
    m = d.add(av.blocks.Constant(np.column_stack([np.arange(n), -np.arange(n)]) * 1.0),
              name="m")
    d.connect(veh.pose, ch.pose)
    d.connect(m.y, ch.message)
    flag = np.zeros(n, dtype=bool)
    flag[0] = True
    fl = d.add(av.blocks.Constant(flag), name="flag")
    val = d.add(av.blocks.Constant(np.arange(n, dtype=float)[:, None] + 100.0), name="val")
    g = d.add(Broadcast(n, radius=0.8, p_loss=0.4, value_dim=1, capacity=capacity),
              name="g")
    d.connect(veh.pose, g.pose)
    d.connect(fl.y, g.flag)
    d.connect(val.y, g.value)
    return d


def test_compiled_engine_delivers_the_same_messages():
    n, kw = 40, dict(t_final=3.0, dt=0.05, seed=5,
                     log=["ch.sender", "ch.received", "g.informed", "g.value"])
    ref = av.simulate(_moving_swarm(n, 0), **kw)
    got = av.simulate(_moving_swarm(n, 0, capacity=48), backend="jax", **kw)
    np.testing.assert_array_equal(got["ch.sender"], ref["ch.sender"])
    np.testing.assert_array_equal(got["g.informed"], ref["g.informed"])
    np.testing.assert_allclose(got["ch.received"], ref["ch.received"], atol=1e-12)
    np.testing.assert_allclose(got["g.value"], ref["g.value"], atol=1e-12)
    s = ref["ch.sender"][2:]
    # the run is not trivial: messages get through and get lost, the news spreads
    assert 0.2 < np.mean(s >= 0) < 0.9
    inf = ref["g.informed"]
    assert inf[0].sum() == 1 and inf[-1].sum() > 5
    # every delivered message is its sender's, and the sender was in range
    # (at the step it was sent: 2 steps earlier) and not lost, per the link draw
    pose = av.simulate(_moving_swarm(n, 0), **{**kw, "log": ["veh.pose"]})["veh.pose"]
    rec = ref["ch.received"]
    for step in (5, 30, 60):
        p = pose[step - 2][:, :2]
        for i in range(n):
            for kk, j in enumerate(ref["ch.sender"][step, i]):
                if j >= 0:
                    assert np.hypot(*(p[j] - p[i])) <= 1.0 + 1e-12
                    np.testing.assert_array_equal(rec[step, i, kk], [j, -j])


def test_gossip_link_loss_rate_and_lowest_index_value():
    # one informed agent, 30 in range: each is reached iff its link survives
    n, p = 31, 0.35
    pos = np.zeros((n, 2))
    pos[1:, 0] = np.linspace(0.1, 0.9, n - 1)
    inf0 = np.zeros(n, bool)
    inf0[0] = True
    key, got = av.core.rng.key(1), []
    for _ in range(300):
        key, sub = av.core.rng.split(key)
        new, _ = gossip_step(inf0, pos, 1.0, p, sub)
        assert new[0]
        got.append(new[1:])
        # the draw is the documented one, link 0 -> j
        lost = av.core.rng.uniform_at(sub, 0, np.arange(1, n)) < p
        np.testing.assert_array_equal(new[1:], ~lost)
    frac = np.mean(got)
    assert abs(frac - (1 - p)) < 4 * np.sqrt(p * (1 - p) / np.size(got))
    # two informed agents reach a third: it takes the lower index's value
    pos = np.array([[0.0, 0], [0.5, 0], [1, 0]])
    new, val = gossip_step([False, True, True], pos[[1, 2, 0]], 0.6,
                           value=np.array([[0.0], [5.0], [6.0]]))
    # agent 0 sits at x=0.5 (both in range): takes agent 1's value
    assert new.tolist() == [True, True, True] and val[:, 0].tolist() == [5.0, 5.0, 6.0]
