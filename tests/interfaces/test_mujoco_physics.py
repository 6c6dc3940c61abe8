"""PhysicsWorld: same ports as the model blocks, lockstep, determinism,
obstacles, quadrotor dynamics against vehicles.Quadrotor."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import PointToPoint
from avblocks.environment import Circle, World, rectangle
from avblocks.vehicles import (
    DiffDrive,
    Quadrotor,
    Unicycle,
    velocity_controlled_quadrotor,
)

from ._mj import need

pytestmark = pytest.mark.mujoco


@pytest.fixture(scope="module")
def mj():
    need("mujoco")
    from avblocks.interfaces import mujoco as avmj
    return avmj


POSE0 = np.array([[0.0, 0.0, 0.0], [2.0, 1.0, np.pi / 2], [-1.0, -2.0, -2.5]])
WAYPOINTS = np.array([[3.0, 3.0], [-2.0, 3.0]])


def _p2p_diagram(vehicle):
    """A closed loop: PointToPoint -> vehicle -> PointToPoint."""
    d = av.Diagram()
    v = d.add(vehicle, name="fleet")
    c = d.add(PointToPoint(WAYPOINTS, n=3, v_max=0.8, gain=1.5), name="drive")
    d.connect(v.pose, c.pose)
    d.connect(c.cmd, v.cmd)
    return d


def test_swap_unicycle_for_physics_changes_nothing_else(mj):
    """The same diagram (same controller, same wires, same names) with the
    model block and with the MuJoCo block: the poses agree to the velocity
    loop's lag. With time constant tau_v = 0.02 s and speeds <= 0.8 m/s the
    lag is <= v tau_v = 1.6 cm per unit of curvature change; we allow 5 cm
    over 8 s (the loops correct the small differences, they don't build up)."""
    scene = mj.Scene()
    scene.add_ground_robots("fleet", POSE0, radius=0.05)   # small: no contacts
    phys = mj.PhysicsWorld(scene, period=0.01)
    assert set(phys.input_ports) == set(Unicycle(POSE0).input_ports) == {"cmd"}
    assert set(phys.output_ports) == {"pose"}
    log = ["fleet.pose", "drive.cmd"]
    r_model = av.simulate(_p2p_diagram(Unicycle(POSE0)), 8.0, dt=0.01, log=log,
                          progress=False)
    r_phys = av.simulate(_p2p_diagram(phys), 8.0, dt=0.01, log=log, progress=False)
    a, b = r_model["fleet.pose"], r_phys["fleet.pose"]
    assert a.shape == b.shape == (801, 3, 3)
    assert np.max(np.linalg.norm(a[:, :, :2] - b[:, :, :2], axis=-1)) < 0.05
    # heading: the first turn commands up to w_max = 8 rad/s; the servo lags
    # by tau_w and the sampled block holds the command dt/2 on average, so
    # the lag is ~ w_max (tau_w + dt/2) = 0.2 rad, and the two closed loops
    # react to it differently for a moment (measured 0.36 rad); then agree
    dth = np.abs(av.utility.wrap_angle(a[:, :, 2] - b[:, :, 2]))
    w_max = np.max(np.abs(r_model["drive.cmd"][:, :, 1]))
    assert np.max(dth) < 2 * w_max * (phys.tau_w + 0.005)
    assert np.max(dth[-100:]) < 0.01
    # and the robots really drove (2.5 m and more, each)
    assert np.min(np.linalg.norm(b[-1, :, :2] - b[0, :, :2], axis=-1)) > 2.5


def test_constant_command_matches_closed_form(mj):
    """v, omega held: the unicycle's arc, x = sin(w t) v / w, y = (1 - cos(w t)) v / w,
    to the servo lag (after the 0.1 s transient, the arc is the exact one
    delayed by tau_v)."""
    scene = mj.Scene()
    scene.add_ground_robots("r", [[0.0, 0.0, 0.0]])
    phys = mj.PhysicsWorld(scene, period=0.01, tau_v=0.01, tau_w=0.01)
    x = phys.initial_state()
    u = {"cmd": np.array([[1.0, 0.5]])}
    for k in range(300):
        x = phys.update(k * 0.01, x, u, np)
    p = phys.output(3.0, x, {}, np)["pose"][0]
    te = 3.0 - 0.01                          # first-order lag delays by tau
    exact = np.array([np.sin(0.5 * te) / 0.5, (1 - np.cos(0.5 * te)) / 0.5, 0.5 * te])
    assert np.allclose(p, exact, atol=0.02), (p, exact)


def test_diffdrive_wheels_port(mj):
    scene = mj.Scene()
    scene.add_ground_robots("r", [[0.0, 0.0, 0.0]], kind="diffdrive", wheel_radius=0.05,
                            track_width=0.3)
    phys = mj.PhysicsWorld(scene, period=0.01)
    assert set(phys.input_ports) == set(DiffDrive([[0.0, 0.0, 0.0]]).input_ports)
    x = phys.initial_state()
    for k in range(200):        # both wheels 10 rad/s -> 0.5 m/s straight
        x = phys.update(k * 0.01, x, {"wheels": np.array([[10.0, 10.0]])}, np)
    p = phys.output(2.0, x, {}, np)["pose"][0]
    assert p[0] == pytest.approx(0.5 * (2.0 - 0.02), abs=5e-3)
    assert abs(p[1]) < 1e-9 and abs(p[2]) < 1e-9


def test_deterministic_and_state_logged(mj):
    """Same diagram twice: bit-identical MuJoCo state logs."""
    def run():
        scene = mj.Scene()
        scene.add_ground_robots("fleet", POSE0, radius=0.3)   # big: they touch
        phys = mj.PhysicsWorld(scene, period=0.01, state_outputs=True)
        d = _p2p_diagram(phys)
        return av.simulate(d, 3.0, dt=0.01, log=["fleet.qpos", "fleet.qvel", "fleet.pose"],
                           progress=False)
    a, b = run(), run()
    assert a["fleet.qpos"].shape == (301, 9)
    assert np.array_equal(a["fleet.qpos"], b["fleet.qpos"])
    assert np.array_equal(a["fleet.qvel"], b["fleet.qvel"])
    assert np.array_equal(a["fleet.qpos"][:, :3], a["fleet.pose"][:, 0, :])


def test_walls_stop_robots(mj):
    """A robot driving at a World wall stops at it: x <= wall - radius (+ the
    contact solver's softness, ~1 cm); a circle obstacle too."""
    world = World([rectangle(2.0, -1.0, 2.5, 1.0), Circle((0.0, 3.0), 0.5)])
    scene = mj.Scene(world)
    scene.add_ground_robots("r", [[0.0, 0.0, 0.0], [0.0, 1.0, np.pi / 2]], radius=0.2)
    phys = mj.PhysicsWorld(scene, period=0.01)
    x = phys.initial_state()
    for k in range(400):
        x = phys.update(k * 0.01, x, {"cmd": np.array([[1.0, 0.0], [1.0, 0.0]])}, np)
    p = phys.output(4.0, x, {}, np)["pose"]
    assert 1.75 < p[0, 0] <= 1.8 + 0.01     # free run would be at x ~ 4
    assert 2.25 < p[1, 1] <= 2.3 + 0.01     # circle at y = 3 - 0.5, robot radius 0.2


def _quad_diagram(quad_block, position0):
    """Velocity set-point -> QuadrotorVelocityControl -> quad block."""
    sub = velocity_controlled_quadrotor(quad_block)   # gains from the block's airframe
    d = av.Diagram()
    s = d.add(sub, name="uav")
    c = d.add(av.blocks.Constant(np.array([[1.0, -0.5, 0.3]])), name="vref")
    d.connect(c.y, s.velocity)
    return d


def test_quadrotor_matches_model_block(mj):
    """The MuJoCo quadrotor and vehicles.Quadrotor under the same velocity
    controller: same ports, and positions within 2 cm over 3 s (MuJoCo
    integrates with semi-implicit Euler at 2 ms, the model with RK4 at 10 ms
    and the wrench held over 10 ms in both)."""
    p0 = np.array([[0.0, 0.0, 2.0]])
    scene = mj.Scene()
    scene.add_quadrotors("uav", p0)
    phys = mj.PhysicsWorld(scene, period=0.01)
    model = Quadrotor(p0)
    assert set(phys.input_ports) == set(model.input_ports)
    assert set(phys.output_ports) == set(model.output_ports)
    for name, port in model.output_ports.items():
        assert phys.output_ports[name].shape == port.shape
    log = ["uav.quad.position", "uav.quad.velocity", "uav.quad.attitude"]
    ra = av.simulate(_quad_diagram(model, p0), 3.0, dt=0.01, log=log, progress=False)
    rb = av.simulate(_quad_diagram(phys, p0), 3.0, dt=0.01, log=log, progress=False)
    pa, pb = ra["uav.quad.position"], rb["uav.quad.position"]
    assert np.max(np.linalg.norm(pa - pb, axis=-1)) < 0.02
    # both reach the set-point velocity
    assert np.allclose(rb["uav.quad.velocity"][-1, 0], [1.0, -0.5, 0.3], atol=0.02)


def test_quadrotor_rates_are_body_frame(mj):
    """A body-x torque on a yawed quadrotor: MuJoCo's angular velocity output
    equals the model's body rates (J domega = tau, from rest)."""
    yaw = 0.7
    q0 = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    scene = mj.Scene(ground=False)
    scene.add_quadrotors("q", [[0.0, 0.0, 5.0]], attitude0=q0, inertia=(0.01, 0.02, 0.03))
    phys = mj.PhysicsWorld(scene, period=0.01)
    x = phys.initial_state()
    w = np.array([[9.81, 0.001, 0.0, 0.0]])
    for k in range(5):
        x = phys.update(k * 0.01, x, {"wrench": w}, np)
    rates = phys.output(0.05, x, {}, np)["rates"][0]
    assert rates == pytest.approx([0.001 / 0.01 * 0.05, 0.0, 0.0], abs=1e-5)


def test_rotor_input(mj):
    """Four equal rotor thrusts of m g / 4 hover (position held)."""
    scene = mj.Scene()
    scene.add_quadrotors("q", [[0.0, 0.0, 1.0]], input="rotors")
    phys = mj.PhysicsWorld(scene, period=0.01)
    assert set(phys.input_ports) == {"rotors"}
    x = phys.initial_state()
    for k in range(100):
        x = phys.update(k * 0.01, x, {"rotors": np.full((1, 4), 9.81 / 4)}, np)
    assert phys.output(1.0, x, {}, np)["position"][0] == pytest.approx([0, 0, 1.0], abs=1e-9)


def test_bad_inputs_raise(mj):
    scene = mj.Scene()
    scene.add_ground_robots("r", [[0.0, 0.0, 0.0]])
    with pytest.raises(av.AvError, match="used twice"):
        scene.add_ground_robots("r", [[0.0, 0.0, 0.0]])
    with pytest.raises(av.AvError, match="whole number of MuJoCo timesteps"):
        mj.PhysicsWorld(scene, period=0.003)
    with pytest.raises(av.AvError, match="tau_v"):
        mj.PhysicsWorld(scene, period=0.01, tau_v=0.001)
    ok = mj.PhysicsWorld(scene, period=0.01)
    assert set(ok.parameters) == {"tau_v", "tau_w"}
    ok.set_parameter("tau_v", 0.05)
    assert float(ok.tau_v) == 0.05
    with pytest.raises(av.AvError, match="tau_v"):
        ok.set_parameter("tau_v", 0.001)
    with pytest.raises(av.AvError, match="scene must be"):
        mj.PhysicsWorld("scene.xml")
    with pytest.raises(av.AvError, match="compiled already"):
        scene.add_ground_robots("r2", [[0.0, 0.0, 0.0]])
    with pytest.raises(av.AvError, match="no dynamic agent group"):
        s2 = mj.Scene()
        s2.add_ground_robots("k", [[0.0, 0.0, 0.0]], kinematic=True)
        mj.PhysicsWorld(s2)


def test_user_mjcf_bodies_mapped(mj):
    xml = """<mujoco><worldbody><geom type="plane" size="5 5 .1"/>
      <body name="car" pos="0 0 .1"><joint type="slide" axis="1 0 0"/>
        <joint type="slide" axis="0 1 0"/><joint type="hinge" axis="0 0 1"/>
        <geom type="box" size=".2 .1 .05" mass="2" contype="0" conaffinity="0"/></body>
      <body name="drone" pos="0 0 1"><freejoint/><geom type="sphere" size=".1" mass="0.5"/>
      </body></worldbody></mujoco>"""
    scene = mj.Scene.from_mjcf(xml, ground_robots={"cars": ["car"]},
                               quadrotors={"drones": ["drone"]})
    phys = mj.PhysicsWorld(scene, period=0.01)
    assert {"cars_cmd", "drones_wrench"} <= set(phys.input_ports)
    x = phys.initial_state()
    u = {"cars_cmd": np.array([[0.5, 0.0]]), "drones_wrench": np.array([[0.5 * 9.81, 0, 0, 0]])}
    for k in range(100):
        x = phys.update(k * 0.01, x, u, np)
    y = phys.output(1.0, x, {}, np)
    assert y["cars_pose"][0, 0] == pytest.approx(0.5 * 0.98, abs=5e-3)
    assert y["drones_position"][0] == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)
    with pytest.raises(av.AvError, match="no such body"):
        mj.Scene.from_mjcf(xml, ground_robots={"cars": ["bus"]})
    with pytest.raises(av.AvError, match="free joint"):
        mj.Scene.from_mjcf(xml, quadrotors={"d": ["car"]})


def test_no_backend_error_names_what_to_install():
    """With no working GL backend the chooser raises MuJoCoUnavailable whose
    message names the Debian packages (run in a fresh process)."""
    need("mujoco")
    code = (
        "import os; os.environ.pop('MUJOCO_GL', None)\n"
        "from avblocks.interfaces.mujoco import _gl\n"
        "_gl.BACKENDS = ('no-such-gl',)\n"
        "m = _gl.import_mujoco()      # physics alone: imports fine\n"
        "m.MjModel.from_xml_string('<mujoco/>')\n"
        "try:\n    _gl.import_mujoco(render=True)\nexcept _gl.MuJoCoUnavailable as e:\n"
        "    print('ERR', e)\n")
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    assert "ERR" in out.stdout, out.stderr
    assert "libosmesa6" in out.stdout and "libegl1" in out.stdout


def test_thrust_and_rotor_limits(mj):
    """thrust_max caps the collective thrust: asking 2 m g with thrust_max =
    1.5 m g accelerates up at 0.5 g (z = g t^2 / 4 after t)."""
    scene = mj.Scene(ground=False)
    scene.add_quadrotors("q", [[0.0, 0.0, 0.0]], thrust_max=1.5 * 9.81)
    phys = mj.PhysicsWorld(scene, period=0.01)
    assert np.all(phys.thrust_max == 1.5 * 9.81)
    x = phys.initial_state()
    for k in range(50):
        x = phys.update(k * 0.01, x, {"wrench": np.array([[2 * 9.81, 0, 0, 0]])}, np)
    z = phys.output(0.5, x, {}, np)["position"][0, 2]
    assert z == pytest.approx(0.5 * 9.81 * 0.5 ** 2 / 2, rel=0.02)


@pytest.mark.jax
def test_compiled_backend_refuses_by_name(mj):
    pytest.importorskip("jax")
    scene = mj.Scene()
    scene.add_ground_robots("fleet", POSE0)
    with pytest.raises(av.AvError, match="fleet"):
        av.simulate(_p2p_diagram(mj.PhysicsWorld(scene)), 0.1, dt=0.01, backend="jax",
                    progress=False)
