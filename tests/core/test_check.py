"""check_block catches each kind of contract violation, and passes good blocks."""

import numpy as np
import pytest

import avblocks as av
from avblocks.core.check import check_block


class Good(av.Block):
    def __init__(self, n):
        super().__init__()
        self.declare_input("u", (n, 2))
        self.declare_output("y", (n, 2))

    def output(self, t, x, u, xp):
        return {"y": 2.0 * u["u"]}


class Mutates(Good):
    def output(self, t, x, u, xp):
        u["u"][:] = 0.0
        return {"y": u["u"]}


class Hidden(Good):
    calls = 0

    def output(self, t, x, u, xp):
        Hidden.calls += 1
        return {"y": u["u"] * Hidden.calls}


class Unseeded(Good):
    def output(self, t, x, u, xp):
        return {"y": u["u"] + np.random.default_rng().normal(size=u["u"].shape)}


class BadShape(Good):
    def output(self, t, x, u, xp):
        return {"y": u["u"][:, :1]}


class FixedN(Good):
    def __init__(self, n):
        super().__init__(3)


class ReadsNonFeedthrough(av.Block):
    def __init__(self, n):
        super().__init__()
        self.declare_input("u", (n, 2), feedthrough=False)
        self.declare_output("y", (n, 2))

    def output(self, t, x, u, xp):
        return {"y": u["u"]}


def test_good_block_passes():
    r = check_block(Good)
    assert r.ok and r.checked_n == [1, 7]


@pytest.mark.parametrize("cls,needle", [
    (Mutates, "modified in place"),
    (Hidden, "differs between two identical calls"),
    (Unseeded, "differs between two identical calls"),
    (BadShape, "has shape (1, 1), declared (1, 2)"),
    (FixedN, "is not the agent count 1"),
    (ReadsNonFeedthrough, "only receives feedthrough inputs"),
])
def test_violations_are_reported(cls, needle):
    r = check_block(cls, raise_on_failure=False)
    assert not r.ok
    assert any(needle in f for f in r.failures), r.failures
    with pytest.raises(av.AvError, match="failure"):
        check_block(cls)


def test_library_blocks_pass():
    for make in (lambda n: av.vehicles.Unicycle(pose0=np.zeros((n, 3))),
                 lambda n: av.controllers.PointToPoint([[1.0, 2.0], [3.0, 4.0]], n=n)):
        assert check_block(make).ok
