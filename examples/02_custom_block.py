"""Write your own block in twenty lines, check it, and run it.

A heading-hold controller: drive at speed v0 while turning toward a fixed
heading, omega = K wrap(heading - theta). Each unicycle's heading error then
decays as exp(-K t), which the script checks against the closed form.
"""

import numpy as np

import avblocks as av


class HeadingHold(av.Block):
    """Ports: pose (N, 3) in; cmd (N, 2) out. omega = K wrap(heading - theta)."""

    def __init__(self, n, heading=0.0, gain=1.0, v0=1.0):
        super().__init__()
        self.n = n
        self.heading = av.core.params.agent_array(heading, n, "HeadingHold", "heading")
        self.gain, self.v0 = gain, v0
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_output("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"))

    def output(self, t, x, u, xp):
        err = av.utility.wrap_angle(self.heading - u["pose"][:, 2], xp)
        return {"cmd": xp.stack([self.v0 + 0 * err, self.gain * err], axis=-1)}


print(av.core.check_block(lambda n: HeadingHold(n)))

N, K = 8, 0.8
theta0 = np.linspace(-2.5, 2.5, N)
d = av.Diagram()
fleet = d.add(av.vehicles.Unicycle(pose0=np.column_stack([np.zeros((N, 2)), theta0])),
              name="fleet")
ctrl = d.add(HeadingHold(N, heading=0.0, gain=K), name="ctrl")
d.connect(fleet.pose, ctrl.pose)
d.connect(ctrl.cmd, fleet.cmd)
res = av.simulate(d, 5.0, dt=0.01, log=[fleet.pose])
err = np.max(np.abs(res[fleet.pose][:, :, 2] - theta0 * np.exp(-K * res.t[:, None])))
print(f"max deviation from theta0 exp(-K t): {err:.2e}")
assert err < 1e-8
