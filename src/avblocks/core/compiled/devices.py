"""Where compiled runs execute: one device, or several with the agent or
run axis split across them.

JAX runs a program on one device unless its inputs say otherwise. With
several devices (several GPUs, or a CPU split into one device per core) a
single run of a large fleet is split along the **agent axis** and an
ensemble along the **run axis**: each input array is placed with a
``NamedSharding`` and XLA's SPMD partitioner divides the whole scanned run,
adding communication only where agents interact (a neighbour search, a
consensus sum). Placement never changes results beyond round-off, only
where the work is done. A split is kept only when XLA partitions the program
without any communication between devices (the agents, or the runs, never
interact); otherwise the runner compiles for one device instead, because a
step that waits on the other device every stage is slower than one device
(the ``waypoints`` scenario, 300 agents, whose law gathers each agent's
waypoint from a flattened table: 3.5 s split, 0.2 s on one device).

JAX gives the CPU one device by default. When avblocks is the first to
import JAX (nothing has imported it yet) it asks for one CPU device per
core (:func:`default_cpu_devices`), unless ``JAX_NUM_CPU_DEVICES`` is set;
import JAX yourself first, or set ``JAX_NUM_CPU_DEVICES=1``, to keep JAX's
default. Measured on W1 (benchmarks/scaling.py --backend jax, 2 cores):
10^4 agents 475 -> 244 us per step, 10^5 agents 3.05 -> 2.78 ms; 256 runs
x 100 agents 2.6 -> 1.8 s.
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from . import _jax
from ._jax import default_cpu_devices  # noqa: F401  (public here since it began)

#: a single run is split along its agent axis from this many agents on
#: (below it the per-step synchronisation costs more than it saves)
MIN_AGENTS_TO_SPLIT = 128


def resolve(devices):
    """The list of devices a runner uses: ``None`` = every local device of
    JAX's default backend; an int k = the first k; or a list of devices."""
    jax = _jax.jax()
    local = jax.local_devices()
    if devices is None:
        return list(local)
    if isinstance(devices, (int, np.integer)) and not isinstance(devices, bool):
        k = int(devices)
        if not 1 <= k <= len(local):
            raise ParameterError("no such number of devices", param="devices",
                                 expected=f"1 .. {len(local)} ({local[0].platform})",
                                 found=k,
                                 hint="on CPU, set JAX_NUM_CPU_DEVICES before JAX starts "
                                      "to split the CPU into more devices")
        return list(local[:k])
    try:
        devs = list(devices)
    except TypeError:
        devs = []
    if not devs or not all(hasattr(d, "platform") for d in devs):
        raise ParameterError("devices must be None, a count or a list of JAX devices",
                             param="devices", found=repr(devices)[:60])
    return devs


SHARDS = ("auto", "agents")


def check_shard(shard, devices, n):
    """``shard`` checked against the devices and the fleet size ``n``."""
    if shard not in SHARDS:
        raise ParameterError("unknown shard", param="shard",
                             expected=" or ".join(repr(s) for s in SHARDS), found=shard)
    if shard == "agents" and len(devices) > 1:
        if not n:
            raise ParameterError("shard='agents' needs a diagram with agents (ports with "
                                 "an agent axis)", param="shard")
        if n % len(devices):
            fit = [k for k in range(len(devices), 0, -1) if n % k == 0][0]
            raise ParameterError("shard='agents' splits the agents evenly over the "
                                 "devices", param="devices",
                                 expected=f"a count that divides {n} agents (e.g. {fit})",
                                 found=len(devices))
    return shard


class Placement:
    """How the inputs of one compiled call are laid out over ``devices``:
    arrays whose leading axis is ``split`` long are divided along it (when
    it divides evenly), everything else is replicated."""

    def __init__(self, devices, split=None):
        jax = _jax.jax()
        self.devices = list(devices)
        self.split = split if (split and len(self.devices) > 1
                               and split % len(self.devices) == 0) else None
        if self.split is None:
            self.key = ("one", self.devices[0].id)
            return
        from jax.sharding import Mesh, NamedSharding, PartitionSpec
        mesh = self.mesh = Mesh(np.array(self.devices), ("d",))
        self.divided = NamedSharding(mesh, PartitionSpec("d"))
        self.replicated = NamedSharding(mesh, PartitionSpec())
        self.key = ("split", self.split, tuple(d.id for d in self.devices))
        self._put = jax.device_put

    def __call__(self, tree):
        """``tree`` (dicts/lists of arrays) placed on the devices."""
        if self.split is None:
            return tree
        return _jax.jax().tree_util.tree_map(self.put, tree)

    def put(self, a):
        """One array placed as :meth:`__call__` places it (on the one
        device when nothing is split); a JAX array, its transfer started."""
        jax = _jax.jax()
        if self.split is None:
            return jax.device_put(a, self.devices[0])
        a = np.asarray(a) if not hasattr(a, "sharding") else a
        where = self.divided if (np.ndim(a) >= 1 and np.shape(a)[0] == self.split) \
            else self.replicated
        if not where.is_fully_addressable and not hasattr(a, "sharding"):
            # devices of other processes (jax.distributed): every process
            # holds the same host array and places its own devices' parts
            return jax.make_array_from_callback(np.shape(a), where,
                                                lambda idx, a=a: a[idx])
        return self._put(a, where)


def host(a):
    """``a`` (a JAX array) as a NumPy array, whole: gathered from every
    process's devices when part of it lives on another process's
    (``jax.distributed``; each process then gets the whole array)."""
    if getattr(a, "is_fully_addressable", True):
        return np.asarray(a)
    from jax.experimental import multihost_utils
    return np.asarray(multihost_utils.process_allgather(a, tiled=True))


_COLLECTIVES = ("all-gather", "all-reduce", "all-to-all", "collective-permute",
                "reduce-scatter", "collective-broadcast")


_VERDICTS: dict = {}


def communicates(executable) -> bool:
    """Whether a compiled split program exchanges data between devices
    (XLA inserted collectives: the agents interact). Remembered per
    executable (programs are cached, so is their verdict)."""
    key = id(executable)
    hit = _VERDICTS.get(key)
    if hit is not None and hit[0] is executable:
        return hit[1]
    try:
        text = executable.as_text()
        verdict = any(c in text for c in _COLLECTIVES)
    except Exception:  # noqa: BLE001 - no text: assume it does, stay safe
        verdict = True
    if len(_VERDICTS) > 64:
        _VERDICTS.clear()
    _VERDICTS[key] = (executable, verdict)
    return verdict


def agents_of(compiled) -> int | None:
    """The fleet size of a diagram: the largest ``agents`` of its ports."""
    n = [p.n for b in compiled.blocks for p in
         list(b._outputs.values()) + list(b._inputs.values()) if p.n]
    return max(n) if n else None
