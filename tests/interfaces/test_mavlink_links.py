"""How the vehicles are reached: connection strings for PX4 SITL (udpin on
14540 + i), ArduPilot SITL (tcp 5760 + 10 i) and a telemetry radio
(serial:DEVICE:BAUD), checked against the strings the SITLs and radios
need, and a flight over a real serial device (a pseudo-terminal: pyserial
and pymavlink's serial link, bridged to the emulator's UDP port)."""

import os
import select
import socket
import subprocess
import sys
import threading
import tty

import numpy as np
import pytest

from avblocks.core.errors import ParameterError
from avblocks.interfaces.mavlink import Drones, connections_from

from ._mavlink import emulator, need_pymavlink, wait_landed
from .conftest import env
from .test_mavlink_flight import _flight


def test_connection_specs_expand_as_the_sitls_number_their_ports():
    # PX4 SITL: instance i sends to 14540 + i
    assert connections_from("udpin:127.0.0.1:14540+", 3) == [
        "udpin:127.0.0.1:14540", "udpin:127.0.0.1:14541", "udpin:127.0.0.1:14542"]
    # ArduPilot SITL: instance i serves TCP 5760 + 10 i
    assert connections_from("tcp:127.0.0.1:5760+10", 3) == [
        "tcp:127.0.0.1:5760", "tcp:127.0.0.1:5770", "tcp:127.0.0.1:5780"]
    assert connections_from("serial:/dev/ttyUSB0:57600,serial:/dev/ttyUSB1:57600") == [
        "serial:/dev/ttyUSB0:57600", "serial:/dev/ttyUSB1:57600"]
    with pytest.raises(ParameterError, match="needs the number of vehicles"):
        connections_from("udpin:127.0.0.1:14540+")
    # a PORT+ whose port is not a number (a spec pasted into another one, as a
    # test written for the old convention did): a clear error, not a ValueError
    for bad in ("udpout:127.0.0.1:udpin:127.0.0.1:44815++", "udpin:127.0.0.1:x+",
                ":14540+"):
        with pytest.raises(ParameterError, match="ends with a port number") as e:
            connections_from(bad, 3)
        assert "udpin:127.0.0.1:14540+" in str(e.value)


@pytest.mark.parametrize("bad, why", [
    ("udp://127.0.0.1:14540", "not a MAVLink connection string"),   # MAVSDK's syntax
    ("127.0.0.1:14540", "not a MAVLink connection string"),
    ("serial:/dev/ttyUSB0", "serial:DEVICE:BAUD"),
])
def test_a_connection_string_it_does_not_know_is_refused_with_examples(bad, why):
    with pytest.raises(ParameterError, match=why) as e:
        Drones(bad)
    assert "udpin:127.0.0.1:14540" in str(e.value) or "serial:/dev/ttyUSB0:57600" in str(
        e.value)


def test_connection_mistakes_are_named_before_anything_else(tmp_path):
    """A pilot's usual slips: MAVSDK's URL or one string for two vehicles
    (the error used to be about the start slots), a port out of range, a
    PORT+ inside a list (OverflowError / ValueError tracebacks before)."""
    with pytest.raises(ParameterError, match="one connection string per vehicle "
                                             r"\(2 vehicles\), or PREFIX:PORT\+"):
        Drones("udpin:127.0.0.1:14540", n=2)
    with pytest.raises(ParameterError, match="port from 1 to 65535"):
        Drones("udpin:127.0.0.1:99999+", n=2)
    with pytest.raises(ParameterError, match="PREFIX:PORT\\+ stands for every vehicle"):
        Drones("udpin:127.0.0.1:14540+,udpin:127.0.0.1:14541")
    p = subprocess.run([sys.executable, "-m", "avblocks", "run", "drone_formation",
                        "--robots", "mavlink", "--set", "agents=2", "--mavlink-connect",
                        "udp://:14540", "--out", str(tmp_path)], env=env(),
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, p.stderr
    assert "not a MAVLink connection string" in p.stderr and "slots" not in p.stderr


def test_a_connection_that_cannot_be_opened_is_refused_by_name(tmp_path):
    """Nothing serves the TCP port, the serial device is not there, another
    program holds the UDP port: a PreflightError naming the vehicle, the
    string and why (ConnectionRefusedError, SerialException tracebacks
    before; the port in use was shared)."""
    need_pymavlink()
    from avblocks.interfaces.flight import PreflightError

    from ._mavlink import free_base_port
    tcp = free_base_port(1, kind=socket.SOCK_STREAM)
    held = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    held.bind(("127.0.0.1", 0))
    udp = held.getsockname()[1]
    try:
        for spec, why in ((f"tcp:127.0.0.1:{tcp}", "Connection refused"),
                          (f"serial:{tmp_path}/ttyNONE:57600", "No such file"),
                          (f"udpin:127.0.0.1:{udp}", "Address already in use")):
            drones = Drones(spec, n=1, wait=1.0)
            with pytest.raises(PreflightError, match=rf"uav1: cannot open the connection "
                                                     rf"'{spec}' \(.*{why}"):
                _flight(drones, [[0.0, 0.0, 1.0]], t_final=0.5)
    finally:
        held.close()


def test_run_help_says_which_connection_reaches_which_autopilot():
    p = subprocess.run([sys.executable, "-m", "avblocks", "run", "--help"], env=env(),
                       capture_output=True, text=True, timeout=60)
    text = " ".join(p.stdout.split())
    assert p.returncode == 0
    for s in ("PX4 SITL (instance i sends to UDP 14540+i): udpin:127.0.0.1:14540+ (the "
              "default", "ArduPilot SITL (instance i serves TCP 5760+10i): "
              "tcp:127.0.0.1:5760+10", "A telemetry radio: serial:/dev/ttyUSB0:57600",
              "udpin:0.0.0.0:14540+ (listens on every interface: name the address on "
              "purpose)"):
        assert s in text, s


class _PtyBridge:
    """A serial device (pseudo-terminal, raw) whose other end is a UDP
    socket where the emulated vehicle sends: what a telemetry radio pair is."""

    def __init__(self, udp_port):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        self.path = os.ttyname(self.slave)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", udp_port))
        self.peer = None
        self.stop = threading.Event()
        self.bytes_up = 0
        self.th = threading.Thread(target=self._run, daemon=True)
        self.th.start()

    def _run(self):
        while not self.stop.is_set():
            r, _, _ = select.select([self.master, self.sock], [], [], 0.05)
            if self.sock in r:
                data, self.peer = self.sock.recvfrom(65535)
                os.write(self.master, data)
            if self.master in r:
                data = os.read(self.master, 65535)
                self.bytes_up += len(data)
                if self.peer is not None:
                    self.sock.sendto(data, self.peer)

    def close(self):
        self.stop.set()
        self.th.join(2)
        self.sock.close()
        os.close(self.master)
        os.close(self.slave)


def test_a_vehicle_flown_over_a_serial_device(tmp_path):
    need_pymavlink()
    try:
        import serial  # noqa: F401  (pyserial, extra [mavlink])
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("pyserial not installed (extra [mavlink])")
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        port = int(spec.split(":")[-1].rstrip("+"))
        bridge = _PtyBridge(port)
        try:
            drones = Drones(f"serial:{bridge.path}:57600", takeoff_height=1.0)
            res = _flight(drones, [[0.5, 0.5, 1.0]], t_final=2.0)
            landed = wait_landed(log, 1)
        finally:
            bridge.close()
    assert sorted(landed) == [1]
    assert np.abs(res["fleet.position"][0, 0, 2] - 1.0) < 0.12
    assert bridge.bytes_up > 1000            # the commander's bytes went over the device
