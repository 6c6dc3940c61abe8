"""LeaderFollower(references_input=True): the `ref` port replaces l_ref/alpha_ref."""

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import LeaderFollower, formation, formation_offsets, references
from avblocks.core.check import check_block


def _inputs(n, seed=0):
    rng = np.random.default_rng(seed)
    pose = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    return pose, rng.uniform(-1, 1, (n, 2))


def test_port_matches_fixed_references():
    leader, l_ref, a_ref = formation("wedge", 7, 1.5, d=0.2)
    fixed = LeaderFollower(leader, l_ref, a_ref, d=0.2, k_l=1.3, k_alpha=0.7)
    port = LeaderFollower(leader, d=0.2, k_l=1.3, k_alpha=0.7, references_input=True)
    assert "ref" in port.input_ports and "ref" not in fixed.input_ports
    assert port.input_ports["ref"].shape == (7, 2)
    pose, cmd = _inputs(7)
    want = fixed.output(0.0, {}, {"pose": pose, "cmd_in": cmd}, np)
    got = port.output(0.0, {}, {"pose": pose, "cmd_in": cmd,
                                "ref": np.column_stack([l_ref, a_ref])}, np)
    for k in ("cmd", "error"):
        np.testing.assert_array_equal(got[k], want[k])
    # the fixed parameters are ignored when the port is on
    ignored = LeaderFollower(leader, 5.0, 1.0, d=0.2, k_l=1.3, k_alpha=0.7,
                             references_input=True)
    got2 = ignored.output(0.0, {}, {"pose": pose, "cmd_in": cmd,
                                    "ref": np.column_stack([l_ref, a_ref])}, np)
    np.testing.assert_array_equal(got2["cmd"], want["cmd"])


def test_fixed_references_still_required_without_port():
    with pytest.raises(av.ParameterError, match="l_ref"):
        LeaderFollower([-1, 0])
    with pytest.raises(av.ParameterError, match="alpha_ref"):
        LeaderFollower([-1, 0], 1.0)


def test_check_block_with_port():
    check_block(lambda n: LeaderFollower(np.r_[-1, np.zeros(n - 1, int)], d=0.3,
                                         references_input=True))


def test_switching_references_in_closed_loop():
    """A Step switches the references from wedge to column at t = 8 s; the
    followers settle into each (the error output goes to ~0)."""
    n, s, dd = 4, 1.0, 0.2
    leader = formation("wedge", n, s, d=dd)[0]
    ref_w = np.column_stack(references(formation_offsets("wedge", n, s), leader, dd))
    ref_c = np.column_stack(references(formation_offsets("column", n, s), leader, dd))
    d = av.Diagram()
    pose0 = np.column_stack([formation_offsets("wedge", n, s) + [[0, 0], [0.3, 0],
                                                                 [0, -0.3], [-0.2, 0.2]],
                             np.zeros(n)])
    fleet = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
    lf = d.add(LeaderFollower(leader, d=dd, k_l=1.5, k_alpha=1.5, references_input=True),
               name="lf")
    go = d.add(av.blocks.Constant(np.tile([0.5, 0.0], (n, 1))), name="go")
    w = d.add(av.blocks.Step(time=8.0, before=0.0, after=1.0, agents=False), name="w")
    mix = d.add(av.blocks.Function(lambda t, w: ref_w + w * (ref_c - ref_w),
                                   inputs={"w": ()}, outputs={"ref": (n, 2)}), name="mix")
    d.connect(w.y, mix.w)
    d.connect(mix.ref, lf.ref)
    d.connect(fleet.pose, lf.pose)
    d.connect(go.y, lf.cmd_in)
    d.connect(lf.cmd, fleet.cmd)
    res = av.simulate(d, 16.0, dt=0.02, log=[lf.error, fleet.pose], log_every=10)
    err = np.abs(res[lf.error]).max(axis=(1, 2))
    t = res.t
    assert err[np.argmin(np.abs(t - 1.0))] > 0.05          # started off formation
    assert err[np.argmin(np.abs(t - 7.8))] < 1e-2           # wedge reached
    assert err[np.argmin(np.abs(t - 8.2))] > 0.3            # switched: big error
    assert err[-1] < 1e-2                                    # column reached
    p = res[fleet.pose][-1]
    # column: everyone on the leader's line, behind it in order
    np.testing.assert_allclose(p[1:, 1], p[0, 1], atol=0.05)
    assert np.all(np.diff(p[:, 0]) < -0.5)
