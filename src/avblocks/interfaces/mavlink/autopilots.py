"""What PX4 and ArduPilot Copter do on a MAVLink link, as data.

One place for the numbers both the commander (:mod:`.drones`) and the
emulator (:mod:`.emulator`) rely on, each with the upstream file or page
it was read from (learned from, not copied):

* message ids and command numbers of the MAVLink common set
  (``message_definitions/v1.0/common.xml``);
* mode numbers: PX4 ``src/modules/commander/px4_custom_mode.h`` (custom
  mode = main << 16 | sub << 24); ArduCopter ``ArduCopter/mode.h``
  (``enum class Number``: STABILIZE 0, GUIDED 4, LOITER 5, RTL 6, LAND 9,
  BRAKE 17);
* the parameters whose values decide what a vehicle does when the link
  or the set-points stop, with their meaning per value (PX4
  ``src/modules/commander/commander_params.c`` and
  ``failsafe/failsafe.cpp``; ArduCopter ``ArduCopter/Parameters.cpp`` and
  ``ArduCopter/events.cpp``), and which of them leave a vehicle flying;
* the parameter encoding on the wire: PX4 copies an integer parameter's
  bytes into PARAM_VALUE's float field, ArduPilot casts it to float
  (MAVLink parameter protocol, "Parameter Encoding";
  ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE`` / ``_C_CAST``).
"""

from __future__ import annotations

import struct

# ---------------------------------------------------------------- MAVLink numbers
MSG = {"HEARTBEAT": 0, "SYS_STATUS": 1, "PARAM_VALUE": 22, "ATTITUDE": 30,
       "ATTITUDE_QUATERNION": 31, "LOCAL_POSITION_NED": 32, "GLOBAL_POSITION_INT": 33,
       "BATTERY_STATUS": 147, "AUTOPILOT_VERSION": 148, "EXTENDED_SYS_STATE": 245,
       "ODOMETRY": 331}
MSG_NAME = {v: k for k, v in MSG.items()}

CMD = {"NAV_RETURN_TO_LAUNCH": 20, "NAV_LAND": 21, "NAV_TAKEOFF": 22, "DO_SET_MODE": 176,
       "COMPONENT_ARM_DISARM": 400, "SET_MESSAGE_INTERVAL": 511, "REQUEST_MESSAGE": 512,
       "REQUEST_AUTOPILOT_CAPABILITIES": 520}
CMD_NAME = {v: k for k, v in CMD.items()}

#: MAV_RESULT
RESULT = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED",
          4: "FAILED", 5: "IN_PROGRESS", 6: "CANCELLED"}
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED, IN_PROGRESS = range(6)

#: MAV_AUTOPILOT / MAV_TYPE / MAV_COMPONENT numbers used here
AUTOPILOT_ARDUPILOTMEGA, AUTOPILOT_INVALID, AUTOPILOT_PX4 = 3, 8, 12
TYPE_GCS, TYPE_GIMBAL = 6, 26
#: MAV_TYPE of multicopters (quad, coaxial, hexa, octo, tri, dodeca, deca)
MULTICOPTER_TYPES = {2: "quadrotor", 3: "coaxial", 13: "hexarotor", 14: "octorotor",
                     15: "tricopter", 29: "dodecarotor", 35: "decarotor"}
COMP_AUTOPILOT1, COMP_MISSIONPLANNER, COMP_GIMBAL = 1, 190, 154

#: REQUEST_DATA_STREAM stream ids (MAV_DATA_STREAM) -> what ArduPilot puts in
#: each group (``libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp``,
#: STREAM_*_msgs, limited to the messages the commander reads).
#: ATTITUDE_QUATERNION and EXTENDED_SYS_STATE are in no group.
APM_STREAM_GROUPS = {2: ("SYS_STATUS",), 6: ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"),
                     10: ("ATTITUDE",), 12: ("BATTERY_STATUS",)}
APM_STREAM_NAMES = {0: "ALL", 2: "EXTENDED_STATUS", 6: "POSITION", 10: "EXTRA1",
                    12: "EXTRA3"}

# ---------------------------------------------------------------- modes
#: PX4 (main mode, sub mode), px4_custom_mode.h
PX4_MODES = {"offboard": (6, 0), "takeoff": (4, 2), "hold": (4, 3), "rtl": (4, 5),
             "land": (4, 6), "position": (3, 0)}
#: ArduCopter mode numbers, ArduCopter/mode.h
APM_MODES = {"guided": 4, "hold": 17, "rtl": 6, "land": 9, "loiter": 5, "stabilize": 0}


def px4_custom_mode(name):
    """HEARTBEAT.custom_mode of a PX4 mode (main << 16 | sub << 24)."""
    main, sub = PX4_MODES[name]
    return (main << 16) | (sub << 24)


# ---------------------------------------------------------------- parameters
#: MAV_PARAM_TYPE numbers
PARAM_INT8, PARAM_INT16, PARAM_INT32, PARAM_REAL32 = 2, 4, 6, 9
_INT_TYPES = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}


def encode_param(value, ptype, autopilot):
    """The float that carries ``value`` in PARAM_VALUE / PARAM_SET.

    PX4 encodes integer parameters byte-wise (their bytes, read as a
    float32); ArduPilot casts them to float (MAVLink parameter protocol,
    "Parameter Encoding")."""
    if ptype in _INT_TYPES and autopilot == "px4":
        raw = struct.pack(_INT_TYPES[ptype], int(value)).ljust(4, b"\0")
        return struct.unpack("<f", raw)[0]
    return float(value)


def decode_param(field, ptype, autopilot):
    """The value a PARAM_VALUE carries (the inverse of :func:`encode_param`)."""
    if ptype in _INT_TYPES and autopilot == "px4":
        raw = struct.pack("<f", field)
        fmt = _INT_TYPES[ptype]
        return struct.unpack(fmt, raw[:struct.calcsize(fmt)])[0]
    if ptype in _INT_TYPES:
        return int(round(field))
    return float(field)


#: Each autopilot's parameters that decide what happens when the set-points
#: or the ground station stop: name -> (MAV_PARAM_TYPE, firmware default,
#: meaning of values). PX4: commander_params.c (v1.14-v1.16), failsafe.cpp
#: (``fromOffboardLossActParam``, ``fromNavDllOrRclActParam``); ArduCopter
#: 4.x: Parameters.cpp, events.cpp (``failsafe_gcs_check``).
PX4_PARAMS = {
    "COM_OF_LOSS_T": (PARAM_REAL32, 1.0, "offboard loss timeout [s]"),
    "COM_OBL_RC_ACT": (PARAM_INT32, 0, {0: "Position mode", 1: "Altitude mode",
                                        2: "Stabilized", 3: "Return mode", 4: "Land mode",
                                        5: "Hold mode", 6: "Terminate", 7: "Disarm"}),
    "COM_RC_IN_MODE": (PARAM_INT32, 3, {0: "RC transmitter only", 1: "joystick only",
                                        2: "RC and joystick with fallback",
                                        3: "RC or joystick, first kept",
                                        4: "stick input disabled"}),
    "NAV_DLL_ACT": (PARAM_INT32, 0, {0: "Disabled", 1: "Hold mode", 2: "Return mode",
                                     3: "Land mode", 5: "Terminate", 6: "Disarm"}),
    "COM_DL_LOSS_T": (PARAM_INT32, 10, "data link loss timeout [s]"),
    "MIS_TAKEOFF_ALT": (PARAM_REAL32, 2.5, "takeoff altitude above home [m]"),
    "MAV_SYS_ID": (PARAM_INT32, 1, "system id"),
}
APM_PARAMS = {
    "FS_GCS_ENABLE": (PARAM_INT8, 0, {0: "Disabled", 1: "RTL", 2: "RTL or continue mission",
                                      3: "SmartRTL or RTL", 4: "SmartRTL or Land", 5: "Land",
                                      6: "Auto DO_LAND_START or RTL", 7: "Brake or Land"}),
    "FS_GCS_TIMEOUT": (PARAM_REAL32, 5.0, "GCS heartbeat loss timeout [s]"),
    "GUID_TIMEOUT": (PARAM_REAL32, 3.0, "GUIDED set-point timeout: stop, not land [s]"),
    "FS_OPTIONS": (PARAM_INT32, 16, "failsafe options bitmask"),
    "SYSID_MYGCS": (PARAM_INT16, 255, "the ground station whose heartbeats count"),
    "SYSID_THISMAV": (PARAM_INT16, 1, "system id"),
}

#: PX4 COM_OBL_RC_ACT values after which a vehicle whose set-points stopped
#: keeps flying (0-2 hand it to the RC sticks; without RC PX4 falls back
#: further, failsafe.cpp ``checkModeFallback``; 5 hovers until the battery
#: failsafe). 3 Return, 4 Land end on the ground; 6 and 7 stop the motors.
PX4_FLYING_LOSS_ACTIONS = {0, 1, 2, 5}
#: ArduCopter FS_GCS_ENABLE values that do not end the flight (0: disabled;
#: in GUIDED the vehicle only stops after GUID_TIMEOUT and hovers).
APM_FLYING_GCS_ACTIONS = {0}


def describe(table, name, value):
    """``"4 (Land mode)"`` for a parameter with named values."""
    meaning = table[name][2]
    if isinstance(meaning, dict):
        return f"{value:g} ({meaning.get(int(value), 'unknown value')})" \
            if isinstance(value, float) else f"{value} ({meaning.get(int(value), 'unknown')})"
    return f"{value:g}" if isinstance(value, float) else str(value)
