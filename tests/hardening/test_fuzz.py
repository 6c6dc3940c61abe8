"""Property-based fuzzing (hypothesis): whatever a hostile user passes, a
failure is an ``AvError`` with a message, never an internal traceback, a
hang or silent garbage.

Every property runs twice: a fast profile (a few dozen examples, for every
CI run) and a long one behind ``@pytest.mark.slow``.
"""

import inspect
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import avblocks as av
from avblocks.scenarios import block_registry, load_scenario
from avblocks.scenarios.loader import builtin_dir

FAST = settings(max_examples=25, deadline=None, database=None,
                suppress_health_check=list(HealthCheck))
LONG = settings(max_examples=400, deadline=None, database=None,
                suppress_health_check=list(HealthCheck))

HOSTILE = st.sampled_from([
    None, 0, 1, 2, 3, -1, -3, 2.5, 0.1, 1e30, 10**30, math.nan, math.inf, -math.inf,
    "abc", "", "1", [], [1.0, 2.0], [[0.0, 0.0, 0.0]] * 3, {}, {"a": 1}, True,
    (2,), np.zeros((3, 2)), np.zeros((3, 3)), np.full((3, 3), np.nan), np.ones(3),
    object(),
])


def _is_clean(e):
    return isinstance(e, av.AvError) and str(e).strip()


def _expect_clean(fn):
    try:
        return fn()
    except av.AvError as e:
        assert _is_clean(e), repr(e)
        return None


# ------------------------------------------------------------ constructors
REGISTRY = sorted(block_registry().items())


def _ctor_property(data):
    name, cls = data.draw(st.sampled_from(REGISTRY), label="block")
    params = [p for p in inspect.signature(cls.__init__).parameters.values()
              if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    kwargs = {}
    for p in params:
        required = p.default is inspect.Parameter.empty
        if required or data.draw(st.booleans(), label=f"set {p.name}"):
            kwargs[p.name] = data.draw(HOSTILE, label=p.name)
    try:
        cls(**kwargs)
    except av.AvError as e:
        assert _is_clean(e), f"{name}({kwargs}): {e!r}"


@FAST
@given(st.data())
def test_fuzz_constructors(data):
    _ctor_property(data)


@pytest.mark.slow
@LONG
@given(st.data())
def test_fuzz_constructors_long(data):
    _ctor_property(data)


# ---------------------------------------------------------- scenario files
SEED_TEXT = (builtin_dir() / "waypoints.yaml").read_text()
TOKENS = ["-1", ".inf", ".nan", "abc", "[]", "{}", "~", "1e400", "&a x", "*a", "[*a, *a]",
          "0", "1000000000", "vehicles.Nope", "{type: [1]}", "'\\xff'", "- -", ": :",
          "$nope", "${agents}", "{zeros: {shape: [-1, 3]}}", "{world: {obstacles: 1}}"]


def _mutate(data, text):
    lines = text.splitlines()
    for _ in range(data.draw(st.integers(1, 4), label="mutations")):
        kind = data.draw(st.sampled_from(["token", "dup", "drop", "byte", "indent"]),
                         label="kind")
        i = data.draw(st.integers(0, max(len(lines) - 1, 0)), label="line")
        if not lines:
            lines = [""]
        if kind == "token":
            line = lines[i]
            if ":" in line:
                key = line.split(":", 1)[0]
                lines[i] = f"{key}: {data.draw(st.sampled_from(TOKENS), label='tok')}"
        elif kind == "dup":
            lines.insert(i, lines[i])
        elif kind == "drop":
            del lines[i]
        elif kind == "indent":
            lines[i] = " " * data.draw(st.integers(0, 5), label="sp") + lines[i].lstrip()
        else:
            b = bytearray(lines[i].encode())
            if b:
                j = data.draw(st.integers(0, len(b) - 1), label="pos")
                b[j] = data.draw(st.integers(0, 255), label="byte")
            lines[i] = b.decode("latin-1")
    return "\n".join(lines) + "\n"


def _scenario_property(data):
    text = _mutate(data, SEED_TEXT)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "s.yaml"
        p.write_bytes(text.encode("latin-1", "replace") if data.draw(
            st.booleans(), label="latin1") else text.encode("utf-8", "replace"))

        def build():
            sc = load_scenario(p).with_overrides({})
            return sc.build(output_dir=Path(tmp) / "out")

        built = _expect_clean(build)
        if built is None:
            return
        d, sim = built
        sim = {**sim, "t_final": 0.02, "dt": 0.01}
        res = _expect_clean(lambda: av.simulate(d, **sim))
        if res is not None:
            assert len(res.t) >= 1


@FAST
@given(st.data())
def test_fuzz_scenario_files(data):
    _scenario_property(data)


@pytest.mark.slow
@LONG
@given(st.data())
def test_fuzz_scenario_files_long(data):
    _scenario_property(data)


# -------------------------------------------------------- simulate arguments
def _ramp():
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((3, 2))), name="c")
    i = d.add(av.blocks.Integrator(np.zeros((3, 2))), name="i")
    d.connect(c.y, i.u)
    return d


ARGS = {
    "t_final": st.sampled_from([0.0, 0.3, 1.0, -1.0, math.nan, math.inf, "1", None, 1e30,
                                0.25]),
    "dt": st.sampled_from([0.1, 0.3, 0.05, 0.0, -0.1, math.nan, math.inf, "x", None,
                           1e-300, 0.07]),
    "solver": st.sampled_from(["rk4", "euler", "RK45", "lsoda", "nope", 3, None]),
    "log": st.sampled_from([None, "i.y", ["i.y", "c.y"], "i.nope", 5, [1], "nope.y"]),
    "log_every": st.sampled_from([1, 2, 0, -1, 2.0, 2.5, math.nan, "2", None]),
    "seed": st.sampled_from([0, 1, -1, 2**70, 1.5, "abc", None]),
    "t0": st.sampled_from([0.0, 1.0, -1.0, math.nan, None, "0"]),
    "max_log_bytes": st.sampled_from([2**31, 0, -1, None, math.inf, "big"]),
    "check_finite": st.sampled_from([True, False, "no", None]),
}


def _simulate_property(data):
    kw = {k: data.draw(v, label=k) for k, v in ARGS.items()
          if k == "t_final" or data.draw(st.booleans(), label=f"use {k}")}
    res = _expect_clean(lambda: av.simulate(_ramp(), **kw))
    if res is not None:
        # not garbage: the integrator of a constant 1 is t - t0
        t0 = res.meta["t0"]
        if "i.y" in res:
            y = res["i.y"][:, :, 0]
            np.testing.assert_allclose(y, np.broadcast_to((res.t - t0)[:, None], y.shape),
                                       atol=1e-6)
        # the run reaches t_final exactly; the log holds every log_every-th step
        assert res.meta["t_final"] == pytest.approx(float(kw["t_final"]))
        every = res.meta["log_every"]
        assert len(res.t) == res.meta["steps"] // every + 1
        assert res.t[-1] == pytest.approx(t0 + (res.meta["steps"] // every) * every
                                          * res.meta["dt"])


@FAST
@given(st.data())
def test_fuzz_simulate_arguments(data):
    _simulate_property(data)


@pytest.mark.slow
@LONG
@given(st.data())
def test_fuzz_simulate_arguments_long(data):
    _simulate_property(data)


# ----------------------------------------------------------- random wirings
def _pool(n):
    return [
        ("const", lambda: av.blocks.Constant(np.ones((n, 2)))),
        ("const3", lambda: av.blocks.Constant(np.ones((n, 3)))),
        ("int", lambda: av.blocks.Integrator(np.zeros((n, 2)))),
        ("gain", lambda: av.blocks.Gain(2.0)),
        ("sat", lambda: av.blocks.Saturation(-1.0, 1.0)),
        ("uni", lambda: av.vehicles.Unicycle(np.zeros((n, 3)))),
        ("p2p", lambda: av.controllers.PointToPoint(np.ones((n, 1, 2)))),
        ("fn", lambda: av.blocks.Function(lambda t, x: x, inputs={"x": None},
                                          outputs={"y": None})),
        ("zoh", lambda: av.blocks.ZeroOrderHold(0.1)),
    ]


def _wiring_property(data):
    n = data.draw(st.integers(1, 3), label="n")
    pool = _pool(n)
    picks = data.draw(st.lists(st.sampled_from(range(len(pool))), min_size=1, max_size=5),
                      label="blocks")
    d = av.Diagram()
    handles = []
    for j, k in enumerate(picks):
        blk = _expect_clean(pool[k][1])
        if blk is None:
            return
        handles.append(d.add(blk, name=f"{pool[k][0]}{j}"))
    outs = [(h, o) for h in handles for o in h.block.output_ports]
    ins = [(h, i) for h in handles for i in h.block.input_ports]
    if outs and ins:
        for _ in range(data.draw(st.integers(0, 2 * len(ins)), label="wires")):
            (hs, o) = data.draw(st.sampled_from(outs), label="src")
            (hd, i) = data.draw(st.sampled_from(ins), label="dst")
            _expect_clean(lambda hs=hs, o=o, hd=hd, i=i: d.connect(getattr(hs, o),
                                                                  getattr(hd, i)))
    if _expect_clean(d.build) is None:
        return
    _expect_clean(lambda: av.simulate(d, 0.2, dt=0.1))


@FAST
@given(st.data())
def test_fuzz_random_wirings(data):
    _wiring_property(data)


@pytest.mark.slow
@LONG
@given(st.data())
def test_fuzz_random_wirings_long(data):
    _wiring_property(data)
