"""A learned (or any parametric) policy as a controller block.

``cmd = squash(f(params, obs))``, row by row over the agents, where ``f``
is a pure function of its parameters and the observation written with
``xp`` (default: a multilayer perceptron, :func:`mlp`). The parameters are
the block's numeric parameters, one weight matrix ``w<k>`` and one bias
``b<k>`` per layer (``w0, b0, w1, b1, w2, b2``...; ``"policy.w0"``), so
a trained policy is set, swept, vmapped and differentiated like any gain,
and the same diagram runs it on the NumPy engine, compiled, live, on the
ROS 2 emulator or in MuJoCo: a policy swaps to robots exactly like a
hand-written controller does. Weights are saved and loaded as ``.npz``.
"""

from __future__ import annotations

import json

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import count

_ACT = {"tanh": lambda x, xp: xp.tanh(x),
        "relu": lambda x, xp: xp.maximum(x, 0.0),
        "elu": lambda x, xp: xp.where(x > 0, x, xp.exp(xp.minimum(x, 0.0)) - 1.0)}
_SQUASH = ("tanh", "clip", "linear")


def mlp_init(sizes, seed=0, *, gain_last=0.01):
    """Weights ``{"w0": (sizes[0], sizes[1]), "b0": (sizes[1],), ...}`` of a
    multilayer perceptron: orthogonal-like scaled Gaussian rows (variance
    ``1/fan_in``), zero biases, the last layer scaled by ``gain_last`` (a
    small initial output, as PPO implementations do)."""
    sizes = [count(s, "mlp_init", "sizes", lo=1) for s in sizes]
    if len(sizes) < 2:
        raise ParameterError("an MLP needs at least input and output sizes", param="sizes",
                             found=sizes)
    rng = np.random.default_rng(int(seed))
    p = {}
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        w = rng.normal(size=(a, b)) / np.sqrt(a)
        if i == len(sizes) - 2:
            w = w * gain_last
        p[f"w{i}"] = w
        p[f"b{i}"] = np.zeros(b)
    return p


def mlp(params, x, xp=np, activation="tanh"):
    """The MLP's raw output: ``h <- act(h W_i + b_i)`` for every layer but the
    last, which is linear. ``params`` as :func:`mlp_init` makes them; works
    with NumPy and ``jax.numpy`` (and under ``jax.grad``)."""
    act = _ACT[activation]
    layers = len([k for k in params if k.startswith("w")])
    h = x
    for i in range(layers):
        h = h @ params[f"w{i}"] + params[f"b{i}"]
        if i < layers - 1:
            h = act(h, xp)
    return h


def squash(y, how, xp=np):
    """Map a raw output to a command in [-1, 1]: ``tanh``, ``clip`` or
    ``linear`` (unbounded)."""
    if how == "tanh":
        return xp.tanh(y)
    if how == "clip":
        return xp.clip(y, -1.0, 1.0)
    return y


class Policy(Block):
    """A parametric policy: observation in, command out, per agent.

    Ports
    -----
    obs : in, (N, obs_dim)
        Observations (shape taken from the wire when ``n`` is not given).
    cmd : out, (N, act_dim)
        ``low + (squash(f(params, obs)) + 1) / 2 * (high - low)`` for the
        bounded squashes, ``f(params, obs)`` for ``"linear"``.

    Parameters
    ----------
    params : dict of str -> array
        The policy's parameters (identifier names), each a numeric
        parameter of the block (``"<block>.<name>"``).
    fn : callable, optional
        ``fn(params, obs, xp) -> (N, act_dim)`` raw output; default
        :func:`mlp` with ``activation``. Must be pure and use ``xp``.
    act_dim : int, optional
        Command size (default: the size of the last bias ``b<L-1>``).
    activation : {"tanh", "relu", "elu"}
        Hidden activation of the default MLP.
    output : {"clip", "tanh", "linear"}
        How the raw output becomes a command (``clip`` matches a Gaussian
        policy trained with clipped actions; ``tanh`` is smooth, for
        gradients through the run).
    low, high : float or (act_dim,)
        Command range for bounded outputs (default [-1, 1]).
    n : int, optional
        Agents (otherwise from the wire).

    Equations
    ---------
    MLP: ``h_0 = obs``, ``h_{i+1} = act(h_i W_i + b_i)``, output
    ``h_{L-1} W_{L-1} + b_{L-1}``.

    Examples
    --------
    >>> import numpy as np
    >>> p = Policy({"w0": np.eye(2), "b0": np.zeros(2)}, n=1, output="clip")
    >>> p.output(0.0, {}, {"obs": np.array([[0.5, 3.0]])}, np)["cmd"]
    array([[0.5, 1. ]])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {'params': {'w0': {'zeros': {'shape': [4, 2]}}, 'b0': {'zeros': {'shape': [2]}}},
               'n': '$agents'}

    def __init__(self, params, *, fn=None, act_dim=None, activation="tanh", output="clip",
                 low=-1.0, high=1.0, n=None):
        super().__init__()
        if not isinstance(params, dict) or not params:
            raise ParameterError("params must be a non-empty dict {name: array}",
                                 block="Policy", param="params", found=type(params).__name__)
        if activation not in _ACT:
            raise ParameterError("unknown activation", block="Policy", param="activation",
                                 expected=sorted(_ACT), found=activation)
        if output not in _SQUASH:
            raise ParameterError("unknown output squash", block="Policy", param="output",
                                 expected=list(_SQUASH), found=output)
        self.fn = fn
        self.activation = activation
        self.squash_ = output
        self.names = tuple(params)
        for k in self.names:
            if not (isinstance(k, str) and k.isidentifier()) or k in ("low", "high"):
                raise ParameterError("parameter names must be identifiers (not low/high)",
                                     block="Policy", param="params", found=repr(k))
            self.declare_parameter(k, np.asarray(params[k], dtype=float))
        if act_dim is None:
            bs = sorted(k for k in self.names if k.startswith("b") and k[1:].isdigit())
            if fn is not None or not bs:
                raise ParameterError("act_dim is needed for a custom fn", block="Policy",
                                     param="act_dim")
            act_dim = int(np.shape(params[max(bs, key=lambda s: int(s[1:]))])[-1])
        self.act_dim = count(act_dim, "Policy", "act_dim", lo=1)
        self.declare_parameter("low", np.broadcast_to(np.asarray(low, float), (self.act_dim,)))
        self.declare_parameter("high", np.broadcast_to(np.asarray(high, float),
                                                       (self.act_dim,)))
        if n is None:
            self.n = None
            self.declare_input("obs")
            self.declare_output("cmd")
        else:
            self.n = count(n, "Policy", "n", lo=1)
            self.declare_input("obs", (self.n, self._obs_dim()))
            self.declare_output("cmd", (self.n, self.act_dim))

    def _obs_dim(self):
        if "w0" in self.names:
            return int(np.shape(self.__dict__["w0"])[0])
        raise ParameterError("n and the observation size cannot be told for a custom fn "
                             "without w0: wire obs and leave n=None", block="Policy",
                             param="n")

    def configure(self, inputs):
        shape = inputs["obs"].shape
        if len(shape) != 2:
            raise ParameterError("obs must be (N, obs_dim)", block="Policy", param="obs",
                                 expected="(N, obs_dim)", found=shape)
        if "w0" in self.names and self.fn is None and shape[1] != self._obs_dim():
            raise ParameterError("observation size does not match the first layer",
                                 block="Policy", param="obs",
                                 expected=f"(N, {self._obs_dim()})", found=shape)
        self.n = shape[0]
        self.redeclare_output("cmd", (shape[0], self.act_dim), "float64")

    @property
    def weights(self):
        """``{name: array}`` of the policy's parameters (current values)."""
        return {k: self.__dict__[k] for k in self.names}

    def raw(self, obs, xp=np):
        p = self.weights
        if self.fn is not None:
            return self.fn(p, obs, xp)
        return mlp(p, obs, xp, self.activation)

    def output(self, t, x, u, xp):
        y = self.raw(u["obs"], xp)
        if self.squash_ == "linear":
            return {"cmd": y}
        s = squash(y, self.squash_, xp)
        return {"cmd": self.low + (s + 1.0) * 0.5 * (self.high - self.low)}

    # ------------------------------------------------------------ files
    def save(self, path):
        """Write the weights and settings to ``path`` (``.npz``). A custom
        ``fn`` is not stored: load with ``Policy.load(path, fn=...)``."""
        meta = {"activation": self.activation, "output": self.squash_,
                "act_dim": self.act_dim, "custom_fn": self.fn is not None,
                "order": list(self.names)}
        np.savez(path, __meta__=np.array(json.dumps(meta)),
                 __low__=np.asarray(self.low), __high__=np.asarray(self.high),
                 **{k: np.asarray(v) for k, v in self.weights.items()})
        return path

    @classmethod
    def load(cls, path, *, fn=None, n=None, **kw):
        """A Policy from a file :meth:`save` (or :func:`save_policy`) wrote.

        The file may come from someone else (a scenario names it): it is
        read as data (no pickle) and only when it is a ``.npz`` whose
        members, as its zip directory declares them, are ``.npy`` arrays
        that inflate to at most ``AVBLOCKS_MAX_MEMORY`` together (the zip
        reader stops each member at its declared size, so a 2 MB file
        cannot inflate to gigabytes); a malformed file is a
        :class:`~avblocks.core.errors.ParameterError` naming it."""
        _check_npz(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
                params = {k: z[k] for k in meta["order"]}
                low, high = z["__low__"], z["__high__"]
            if not isinstance(meta.get("act_dim"), int):
                raise TypeError("act_dim")
            opts = {"activation": meta["activation"], "output": meta["output"],
                    "act_dim": meta["act_dim"], "low": low, "high": high}
        except MemoryError:
            raise ParameterError("a policy file declares arrays that do not fit in memory",
                                 block="Policy", param="path", found=str(path)) from None
        except (KeyError, TypeError, ValueError, AttributeError, EOFError, OSError,
                RecursionError) as e:
            raise ParameterError(f"not a policy file Policy.save wrote ({type(e).__name__}: "
                                 f"{str(e)[:120]})", block="Policy", param="path",
                                 found=str(path)) from None
        if meta.get("custom_fn") and fn is None:
            raise ParameterError("this policy was saved with a custom fn: pass fn=",
                                 block="Policy", param="fn", found=str(path))
        opts.update(kw)
        return cls(params, fn=fn, n=n, **opts)


#: Largest policy file's arrays, inflated (bytes): a network's weights are
#: kilobytes to megabytes; this bounds what a small compressed file can
#: make the reader allocate.
MAX_POLICY_BYTES = 256 * 1024**2


def _check_npz(path):
    """Refuse a policy file that is not a zip of ``.npy`` members whose
    declared sizes fit in :func:`~avblocks.core.memlimit.memory_limit`,
    before NumPy reads any of it."""
    import zipfile

    from ..core.memlimit import describe, too_large
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
    except (OSError, zipfile.BadZipFile, ValueError) as e:
        raise ParameterError(f"not a policy file (.npz): {e}", block="Policy", param="path",
                             found=str(path)) from None
    bad = [i.filename for i in infos if not i.filename.endswith(".npy")]
    if bad or not infos:
        raise ParameterError("a policy file holds .npy arrays only", block="Policy",
                             param="path", found=bad[:3] or str(path))
    need = sum(i.file_size for i in infos)
    if need > MAX_POLICY_BYTES:
        raise ParameterError(f"a policy file whose arrays inflate to {need / 1e6:,.0f} MB, "
                             f"more than {MAX_POLICY_BYTES / 1e6:,.0f} MB",
                             block="Policy", param="path", found=str(path),
                             hint="a policy is a network's weights: kilobytes to megabytes")
    if too_large(need):
        raise ParameterError(f"a policy file whose arrays inflate to {describe(need)}",
                             block="Policy", param="path", found=str(path))


def save_policy(path, params, *, activation="tanh", output="clip", low=-1.0, high=1.0):
    """Save MLP weights (e.g. straight from a training loop) as a Policy file."""
    p = Policy({k: np.asarray(v) for k, v in params.items()}, activation=activation,
               output=output, low=low, high=high)
    return p.save(path)
