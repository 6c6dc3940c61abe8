"""MAVSDK (the C++ library, through the ``mavsdk`` package's ctypes
wrapper; nothing of avblocks is imported here) flies one vehicle through
its own Action and Offboard plugins, as its examples do: connect, read
two fail-safe parameters, set the takeoff altitude, arm, take off,
offboard velocity north, hold, land. Run as a subprocess by
test_mavlink_mavsdk.py (a crash of the native library cannot take pytest
down); prints one JSON object with what MAVSDK saw and when.

Usage: python _mavsdk_flight.py CONNECTION_URL TAKEOFF_ALT V_NORTH SECONDS
"""

import json
import sys
import time


def main():
    url, alt, v_north, seconds = sys.argv[1], *map(float, sys.argv[2:5])
    from mavsdk import ComponentType, Configuration, Mavsdk
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.offboard import Offboard, VelocityNedYaw
    from mavsdk.plugins.param import Param
    from mavsdk.plugins.telemetry import LandedState, Telemetry

    out = {"steps": []}

    def step(name, **kw):
        out["steps"].append({"step": name, "wall": time.time(), **kw})

    cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    m = Mavsdk(cfg)
    try:
        out["version"] = m.version()
        out["connection"] = str(m.add_any_connection(url))
        system = m.first_autopilot(15.0)
        if system is None:
            step("no autopilot")
            return out
        step("connected")
        param, action = Param(system), Action(system)
        offboard, telemetry = Offboard(system), Telemetry(system)
        out["COM_OBL_RC_ACT"] = param.get_param_int("COM_OBL_RC_ACT")
        out["COM_OF_LOSS_T"] = param.get_param_float("COM_OF_LOSS_T")
        action.set_takeoff_altitude(alt)
        out["takeoff_altitude"] = action.get_takeoff_altitude()
        action.arm()
        step("armed")
        action.takeoff()
        step("takeoff")
        t_end = time.monotonic() + 20
        while time.monotonic() < t_end:
            pv = telemetry.position_velocity_ned()
            if abs(-pv.position.down_m - alt) < 0.05 and abs(pv.velocity.down_m_s) < 0.05:
                break
            time.sleep(0.1)
        step("up", down_m=pv.position.down_m)
        offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        time.sleep(1.5)                 # PX4: more than a second of set-points first
        offboard.start()
        step("offboard")
        offboard.set_velocity_ned(VelocityNedYaw(v_north, 0.0, 0.0, 0.0))
        step("velocity", north_m_s=v_north)
        time.sleep(seconds)
        offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        step("stop")
        time.sleep(1.0)
        pv = telemetry.position_velocity_ned()
        step("stopped", north_m=pv.position.north_m, down_m=pv.position.down_m)
        offboard.stop()
        action.land()
        step("land")
        t_end = time.monotonic() + 20
        while time.monotonic() < t_end and telemetry.landed_state() != LandedState.ON_GROUND:
            time.sleep(0.1)
        step("landed", landed_state=int(telemetry.landed_state()))
        # PX4 disarms after it detects the landing (COM_DISARM_LAND, 2 s by
        # default); the disarm reaches MAVSDK with the next HEARTBEAT (1 Hz),
        # which may come after the EXTENDED_SYS_STATE saying "on ground"
        t_end = time.monotonic() + 5
        while time.monotonic() < t_end and telemetry.armed():
            time.sleep(0.1)
        step("disarmed", armed=bool(telemetry.armed()))
        return out
    finally:
        m.destroy()
        cfg.destroy()


if __name__ == "__main__":
    try:
        result = main()
    except Exception as e:  # noqa: BLE001 - reported to the test, which fails
        result = {"error": f"{type(e).__name__}: {e}"}
    print(json.dumps(result), flush=True)
