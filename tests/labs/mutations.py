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
