"""Deliberately wrong solutions of the labs, as small patches of the
reference solutions in ``solutions/``: each is one piece of a solution
(``find``, which must occur exactly once) and what replaces it. A wrong
solution is written at test time (:func:`write`), so a change to a
reference solution changes its wrong variants with it; a patch whose
``find`` no longer matches fails with its name instead of testing stale
code."""

from __future__ import annotations

from pathlib import Path

SOLUTIONS = Path(__file__).resolve().parent / "solutions"

#: (lab, kind) -> (file in solutions/, find, replace)
MUTATIONS = {
    # lab 1: an index past the pose's columns; cmd declared (N, 3); turn rate negated
    (1, "crash"): ("lab1_kinematics.py", "pose[:, 2]\n", "pose[:, 3]\n"),
    (1, "wrong_shape"): ("lab1_kinematics.py", 'declare_input("cmd", (self.n, 2)',
                         'declare_input("cmd", (self.n, 3)'),
    (1, "wrong_sign"): ("lab1_kinematics.py", "v * xp.sin(th), w]", "v * xp.sin(th), -w]"),
    # lab 2: raises for a far goal; (2, N) stacked; the angular term negated
    (2, "crash"): ("lab2_go_to_goal.py", "        wx, wy = k * ex, k * ey\n",
                   "        wx, wy = k * ex, k * ey\n        if xp.any(norm > 3.0):\n"
                   '            raise ValueError("goal too far")\n'),
    (2, "wrong_shape"): ("lab2_go_to_goal.py", "/ self.d], axis=-1)", "/ self.d], axis=0)"),
    (2, "wrong_sign"): ("lab2_go_to_goal.py", "(-s * wx + c * wy) / self.d",
                        "(s * wx - c * wy) / self.d"),
    # lab 3: an assertion that fails; (2, N) stacked; the leader's turn rate negated
    (3, "crash"): ("lab3_formation.py", "    zeta = xp.arctan2(dy, dx)\n",
                   "    zeta = xp.arctan2(dy, dx)\n"
                   '    assert xp.all(l > 1.0), "followers too close"\n'),
    (3, "wrong_shape"): ("lab3_formation.py", "return xp.stack([v, w], axis=-1)",
                         "return xp.stack([v, w], axis=0)"),
    (3, "wrong_sign"): ("lab3_formation.py", "/ l * v0 + w0", "/ l * v0 - w0"),
    # lab 4: an index past the end; velocity flattened; u = +K L x
    (4, "crash"): ("lab4_consensus.py", "    a = np.asarray(adjacency, dtype=float)\n",
                   "    a = np.asarray(adjacency, dtype=float)\n"
                   "    a = a / a.sum(axis=1).min(initial=0.0) * 0 + a[len(a)]\n"),
    (4, "wrong_shape"): ("lab4_consensus.py", '{"velocity": -self.gain * (lap @ p)}',
                         '{"velocity": (-self.gain * (lap @ p)).ravel()}'),
    (4, "wrong_sign"): ("lab4_consensus.py", '{"velocity": -self.gain * (lap @ p)}',
                        '{"velocity": self.gain * (lap @ p)}'),
    # lab 5, the safety filter: raises without a neighbour; one column; a_ij reversed
    (5, "crash"): ("lab5_safety.py", "    has = neighbor >= 0\n",
                   "    has = neighbor >= 0\n    if not xp.all(has):\n"
                   '        raise KeyError("agent without a neighbour")\n'),
    (5, "wrong_shape"): ("lab5_safety.py", "* a, u_nom)\n", "* a, u_nom)[:, :1]\n"),
    (5, "wrong_sign"): ("lab5_safety.py", "a = position - position[xp.where(has, neighbor, 0)]",
                        "a = position[xp.where(has, neighbor, 0)] - position"),
    # lab 5, flocking: raises for a short range; (D, N) returned; n_ij = q_i - q_j
    (5, "flock_crash"): ("lab5_safety.py", "    s = (root - 1.0) / eps\n",
                         "    s = (root - 1.0) / eps\n    if r < 1.5 * d:\n"
                         '        raise ValueError("range too short for a flock")\n'),
    (5, "flock_wrong_shape"): ("lab5_safety.py", "return c1 * grad + c2 * align",
                               "return (c1 * grad + c2 * align).T"),
    (5, "flock_wrong_sign"): ("lab5_safety.py",
                              "position[None, :, :] - position[:, None, :]          # q_j - q_i",
                              "position[:, None, :] - position[None, :, :]          # q_i - q_j"),
    # lab 6: raises when a robot is silent; (2, N) returned; only the silent robot held
    (6, "crash"): ("lab6_robots.py", '        everyone = xp.all(u["fresh"])\n',
                   '        everyone = xp.all(u["fresh"])\n        if not everyone:\n'
                   '            raise RuntimeError("a robot is silent")\n'),
    (6, "wrong_shape"): ("lab6_robots.py", "0.0 * law)}", "0.0 * law).T}"),
    # issue 46, mistakes that used to pass or get a poor message:
    # lab 1: the turn rate wrapped like an angle; float32 numbers; a list; a write into the state
    (1, "wrap_rate"): ("lab1_kinematics.py", "v * xp.sin(th), w]",
                       "v * xp.sin(th), av.utility.wrap_angle(w, xp)]"),
    (1, "float32"): ("lab1_kinematics.py", "/ track], axis=-1)",
                     "/ track], axis=-1).astype(np.float32)"),
    (1, "list"): ("lab1_kinematics.py",
                  "return np.stack([radius * (wr + wl) / 2, radius * (wr - wl) / track], "
                  "axis=-1)",
                  "return [radius * (wr + wl) / 2, radius * (wr - wl) / track]"),
    (1, "inplace"): ("lab1_kinematics.py", "        v, w, th = cmd[:, 0], cmd[:, 1], pose[:, 2]\n",
                     "        pose[:, 2] = (pose[:, 2] + np.pi) % (2 * np.pi) - np.pi\n"
                     "        v, w, th = cmd[:, 0], cmd[:, 1], pose[:, 2]\n"),
    # lab 2: the look-ahead point computed in the pose input
    (2, "inplace"): ("lab2_go_to_goal.py",
                     "        ex = self.goal[:, 0] - pose[:, 0] - self.d * c\n"
                     "        ey = self.goal[:, 1] - pose[:, 1] - self.d * s\n",
                     "        pose[:, 0] += self.d * c          # the look-ahead point, in place\n"
                     "        pose[:, 1] += self.d * s\n"
                     "        ex = self.goal[:, 0] - pose[:, 0]\n"
                     "        ey = self.goal[:, 1] - pose[:, 1]\n"),
    # lab 3: the follower's heading wrapped in place
    (3, "inplace"): ("lab3_formation.py", "    zeta = xp.arctan2(dy, dx)\n",
                     "    zeta = xp.arctan2(dy, dx)\n"
                     "    pose[:, 2] = wrap(pose[:, 2], xp)        # headings in (-pi, pi]\n"),
    # lab 5: the correction written into u_nom in place
    (5, "inplace"): ("lab5_safety.py",
                     "    return xp.where(has[:, None], u_nom + (short / a2)[:, None] * a, "
                     "u_nom)\n",
                     "    u_nom[has] += (short / a2)[has, None] * a[has]      # in place\n"
                     "    return u_nom\n"),
    # lab 6: a hold that latches (in an attribute; in a discrete state)
    (6, "latch"): ("lab6_robots.py",
                   '        everyone = xp.all(u["fresh"])\n'
                   '        return {"cmd": xp.where(everyone, law, 0.0 * law)}\n',
                   '        self.held = getattr(self, "held", False) or '
                   'not bool(xp.all(u["fresh"]))\n'
                   '        return {"cmd": xp.where(self.held, 0.0 * law, law)}\n'),
    (6, "latch_state"): ("lab6_robots.py",
                         '        self.declare_output("cmd", (self.n, 2), unit="m/s, rad/s")\n\n'
                         '    def output(self, t, x, u, xp):\n'
                         '        law = av.controllers.point_to_point_law(u["pose"], '
                         'xp.asarray(self.goal), self.d,\n'
                         '                                                self.gain, '
                         'self.v_max, xp)\n'
                         '        everyone = xp.all(u["fresh"])\n'
                         '        return {"cmd": xp.where(everyone, law, 0.0 * law)}\n',
                         '        self.declare_output("cmd", (self.n, 2), unit="m/s, rad/s")\n'
                         '        self.declare_discrete_state("held", False)\n\n'
                         '    def output(self, t, x, u, xp):\n'
                         '        law = av.controllers.point_to_point_law(u["pose"], '
                         'xp.asarray(self.goal), self.d,\n'
                         '                                                self.gain, '
                         'self.v_max, xp)\n'
                         '        held = x["held"] | ~xp.all(u["fresh"])\n'
                         '        return {"cmd": xp.where(held, 0.0 * law, law)}\n\n'
                         '    def update(self, t, x, u, xp):\n'
                         '        return {"held": x["held"] | ~xp.all(u["fresh"])}\n'),
    (6, "wrong_sign"): ("lab6_robots.py",
                        '        everyone = xp.all(u["fresh"])\n'
                        '        return {"cmd": xp.where(everyone, law, 0.0 * law)}\n',
                        '        return {"cmd": xp.where(u["fresh"][:, None], law, '
                        '0.0 * law)}\n'),
    # lab 7, learning: a crash on a contact; observations transposed; the
    # progress term reversed; and the realistic mistakes: the collision penalty
    # missing, the goal in world coordinates, unnormalised ranges, the other
    # agents unsorted, a hard-coded team of 3, the contact history updated in
    # place, a policy that did not learn
    (7, "crash"): ("lab7_learning.py", "    first = contact & ~hit\n",
                   "    first = contact & ~hit\n    if xp.any(contact):\n"
                   '        raise RuntimeError("an agent touched something")\n'),
    (7, "wrong_shape"): ("lab7_learning.py", "xp.reshape(rel, (n, 2 * (n - 1)))], axis=-1)",
                         "xp.reshape(rel, (n, 2 * (n - 1)))], axis=-1).T"),
    (7, "wrong_sign"): ("lab7_learning.py", 'params["progress"] * (prev - d)',
                        'params["progress"] * (d - prev)'),
    (7, "no_collision"): ("lab7_learning.py",
                          '            - params["collision"] * contact - params["proximity"]',
                          '            - params["proximity"]'),
    (7, "world_frame"): ("lab7_learning.py", "xp.concatenate([goals - position, position",
                         "xp.concatenate([goals, position"),
    (7, "unnormalised"): ("lab7_learning.py", "ranges / max_range,", "ranges,"),
    (7, "unsorted"): ("lab7_learning.py",
                      "    rel = xp.take_along_axis(rel, order[:, :, None], axis=1)\n", ""),
    (7, "agents"): ("lab7_learning.py", "    n = position.shape[0]\n    j = np.arange",
                    "    n = 3                                              # our team\n"
                    "    j = np.arange"),
    (7, "inplace"): ("lab7_learning.py", "    success = at & ~(hit | contact)\n",
                     "    hit |= contact                           # remember the contact\n"
                     "    success = at & ~hit\n"),
    (7, "untrained"): ("lab7_learning.py", "return {k: z[k] for k in z.files}",
                       "return {k: z[k] * 0.01 for k in z.files}"),
    # lab 8, estimation: a crash near a landmark; the corrected mean transposed;
    # the sign of d x / d theta in F; and the realistic mistakes: the bearing's
    # Jacobian with the wrong sign, the bearing innovation not wrapped, the
    # process noise in the robot's frame, the covariance not symmetrised or not
    # updated, the update predicting from the prediction, a write into the mean
    (8, "crash"): ("lab8_estimation.py", "    rho = xp.sqrt(q2)\n",
                   "    rho = xp.sqrt(q2)\n    if xp.any(rho < 3.0):\n"
                   '        raise ValueError("a landmark is too close")\n'),
    (8, "wrong_shape"): ("lab8_estimation.py",
                         '    p = (xp.eye(3) - gain @ jac) @ cov\n    return {"mean": new,',
                         '    p = (xp.eye(3) - gain @ jac) @ cov\n    return {"mean": new.T,'),
    (8, "wrong_sign"): ("lab8_estimation.py", "[one, zero, -dt * v * s]",
                        "[one, zero, dt * v * s]"),
    (8, "jacobian_h"): ("lab8_estimation.py", "[dy / q2, -dx / q2, zero - 1.0]",
                        "[-dy / q2, dx / q2, zero - 1.0]"),
    (8, "unwrapped"): ("lab8_estimation.py",
                       "    innov = xp.stack([innov[..., 0], av.utility.wrap_angle(innov[..., 1], "
                       "xp)], axis=-1)\n", ""),
    (8, "body_frame"): ("lab8_estimation.py",
                        "    noise = rot @ xp.diag(xp.asarray(q) ** 2) @ xp.swapaxes(rot, -1, -2)",
                        "    noise = xp.diag(xp.asarray(q) ** 2)"),
    (8, "asymmetric"): ("lab8_estimation.py",
                        '    p = (xp.eye(3) - gain @ jac) @ cov\n'
                        '    return {"mean": new, "cov": (p + xp.swapaxes(p, -1, -2)) / 2}',
                        '    p = (xp.eye(3) - gain @ jac) @ cov\n'
                        '    return {"mean": new, "cov": p}'),
    (8, "no_update"): ("lab8_estimation.py",
                       '    p = (xp.eye(3) - gain @ jac) @ cov\n'
                       '    return {"mean": new, "cov": (p + xp.swapaxes(p, -1, -2)) / 2}',
                       '    return {"mean": new, "cov": cov}'),
    (8, "predict_prior"): ("lab8_estimation.py",
                           '        return ekf_predict(post["mean"], post["cov"], u["cmd"], '
                           'self.dt, self.q, xp)',
                           '        return ekf_predict(x["mean"], x["cov"], u["cmd"], self.dt, '
                           'self.q, xp)'),
    (8, "inplace"): ("lab8_estimation.py",
                     "    new = xp.stack([mean[:, 0] + dt * v * c, mean[:, 1] + dt * v * s,\n"
                     "                    av.utility.wrap_angle(th + dt * w, xp)], axis=-1)\n",
                     "    mean[:, 0] += dt * v * c                 # move the estimate\n"
                     "    mean[:, 1] += dt * v * s\n"
                     "    mean[:, 2] = av.utility.wrap_angle(th + dt * w, xp)\n"
                     "    new = mean\n"),
}


def source(number, kind) -> str:
    """The text of wrong solution ``kind`` of lab ``number``."""
    name, find, replace = MUTATIONS[number, kind]
    text = (SOLUTIONS / name).read_text()
    found = text.count(find)
    if found != 1:
        raise AssertionError(f"wrong solution lab{number}_{kind}: its patch expects "
                             f"{find!r} once in solutions/{name}, found it {found} times "
                             "(update MUTATIONS in tests/labs/mutations.py)")
    return text.replace(find, replace)


def write(folder, number, kind) -> Path:
    """Wrong solution ``kind`` of lab ``number`` written as
    ``folder/lab<number>_<kind>.py`` (the name its messages quote)."""
    path = Path(folder) / f"lab{number}_{kind}.py"
    path.write_text(source(number, kind))
    return path
