"""Which controller drives a task's vehicles: the scripted law, or a
trained policy reading the task's observation."""

from __future__ import annotations

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import count

#: The ``policy`` values that mean "no policy: pass the scripted law through".
SCRIPTED = (None, "", "scripted")


class TaskCommand(Block):
    """The velocity command of a learning task: the scripted law's, or a
    trained policy's, chosen by one parameter.

    A task scenario wires both its scripted law (``scripted``) and its task
    block's observation (``obs``) into this block; ``policy`` picks which
    one drives the vehicles, so a scenario file runs a trained network
    with ``--set controller=policy.npz`` and nothing else changes.

    Ports
    -----
    scripted : in, (N, 2) [m/s], the scripted law's velocity command
    obs : in, (N, k), the task's observation (shape from the wire)
    velocity : out, (N, 2) [m/s]

    Parameters
    ----------
    n : int
        Agents.
    policy : str, optional
        ``"scripted"`` (or None): pass ``scripted`` through. Otherwise the
        path of a ``.npz`` file written by
        :meth:`avblocks.controllers.Policy.save` (weights and settings; read
        with ``allow_pickle=False``, nothing in it is executed).
    speed : float
        [m/s] per unit of the policy's command.

    Numeric parameters
    ------------------

    ``speed`` (read at every call: ``"command.speed"``); it scales a
    policy's command only (the scripted command passes through as is).
    ``policy`` and ``n`` are structural.

    Equations
    ---------
    ``velocity = scripted`` without a policy, else
    ``velocity = speed * pi(obs)`` with ``pi`` the
    :class:`~avblocks.controllers.Policy` (its command in ``[-1, 1]^2``).

    Examples
    --------
    >>> import numpy as np
    >>> c = TaskCommand(1)
    >>> c.output(0.0, {}, {"scripted": np.array([[0.3, 0.4]]),
    ...                    "obs": np.zeros((1, 4))}, np)["velocity"]
    array([[0.3, 0.4]])
    """

    example = {"n": "$agents"}
    parameter_info = {"n": {"bounds": [1, None]}}

    def __init__(self, n, *, policy="scripted", speed=1.0):
        super().__init__()
        self.n = n = count(n, "TaskCommand", "n", lo=1)
        if policy is not None and not isinstance(policy, str):
            raise ParameterError("policy must be 'scripted' or the path of a .npz policy",
                                 block="TaskCommand", param="policy",
                                 found=type(policy).__name__)
        self.policy = policy
        self.net = None
        if policy not in SCRIPTED:
            from ..controllers import Policy
            try:
                self.net = Policy.load(str(policy), n=n)
            except OSError as e:
                raise ParameterError(f"cannot read the policy file: {e}", block="TaskCommand",
                                     param="policy", found=str(policy)) from None
            if self.net.act_dim != 2:
                raise ParameterError("the policy must command 2 components per agent",
                                     block="TaskCommand", param="policy",
                                     expected=2, found=self.net.act_dim)
        self.declare_parameter("speed", speed, bounds=(0, None), unit="m/s")
        self.declare_input("scripted", (n, 2), unit="m/s")
        self.declare_input("obs")
        self.declare_output("velocity", (n, 2), unit="m/s")

    def configure(self, inputs):
        shape = inputs["obs"].shape
        if len(shape) != 2 or shape[0] != self.n:
            raise ParameterError("obs must be (N, k)", block="TaskCommand", param="obs",
                                 expected=f"({self.n}, k)", found=shape)
        if self.net is not None:
            self.net.configure(inputs)

    def output(self, t, x, u, xp):
        if self.net is None:
            return {"velocity": u["scripted"]}
        return {"velocity": self.speed * self.net.output(t, x, {"obs": u["obs"]}, xp)["cmd"]}
