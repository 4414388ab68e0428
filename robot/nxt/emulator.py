"""An NXT brick on a pseudo-terminal, for testing the driver without hardware.

`NXTEmulator` opens a pty (`os.openpty`) and answers LEGO direct commands on it the way
the brick does over Bluetooth (2-byte length header, reply type 0x02, opcode echo, status
byte; see `robot.nxt.protocol`). It simulates Foster et al.'s robot (section III): two
wheel motors (B left, C right) of a differential drive in a rectangular room, front and
rear touch bumpers (sensor ports 1, 2), the LEGO ultrasonic (port 3) and the HiTechnic
compass (port 4) on I2C, and a camera whose shutter fires when motor port A is powered
(the photo lands in `camera_dir`, as the Eye-Fi card delivers it to the host).

Faults on demand: garbage bytes before a reply, dropped replies, an error status, and the
port disappearing (`unplug`; `replug` brings it back under the same `link` path).
World frame of the simulation: metres, radians, room centred at the origin.
"""

from __future__ import annotations

import os
import select
import struct
import threading
import time
import tty
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robot.nxt import protocol as P


@dataclass(frozen=True)
class EmulatorConfig:
    wheel_radius_m: float = 0.028
    """Wheel radius of the simulated robot (m)."""
    track_m: float = 0.12
    """Distance between the two wheels (m)."""
    robot_radius_m: float = 0.1
    """Footprint radius; the robot is blocked (and bumps) when it would touch a wall (m)."""
    room_half_size_m: tuple[float, float] = (2.0, 1.5)
    """Half width and half depth of the rectangular room (m)."""
    full_speed_deg_s: float = 900.0
    """Wheel speed at power 100 (degrees of wheel rotation per second)."""
    time_scale: float = 1.0
    """Simulated seconds per wall-clock second (tests run the brick fast)."""
    battery_mv: int = 7800
    """Battery voltage reported (mV)."""
    sleep_timeout_ms: int = 600000
    """What KEEPALIVE reports (ms before the brick sleeps)."""
    north_rad: float = np.pi / 2
    """World angle of magnetic north; the compass reads degrees clockwise from it."""
    i2c_pending_polls: int = 1
    """LSGETSTATUS answers "pending" this many times after each LSWRITE, as the bus does."""
    image_size: tuple[int, int] = (64, 48)
    """(width, height) of the photos the simulated camera writes (px)."""
    reply_latency_s: float = 0.0
    """Wall-clock delay (s) before each reply goes out, while the world moves on: a
    Bluetooth link's round trip is tens of milliseconds, long enough for a started wheel
    to turn a good way before the next command reaches the brick."""


@dataclass
class _Motor:
    power: int = 0
    mode: int = 0
    regulation: int = 0
    turn_ratio: int = 0
    run_state: int = P.RUN_IDLE
    tacho_limit: int = 0
    tacho: float = 0.0
    block_tacho: float = 0.0
    rotation: float = 0.0

    @property
    def running(self) -> bool:
        return bool(self.mode & P.MODE_ON) and self.run_state != P.RUN_IDLE and self.power != 0


@dataclass
class _Faults:
    garbage: bytes = b""  # written before the next reply
    drop: int = 0  # replies to swallow
    status: dict = field(default_factory=dict)  # opcode -> [status, times]
    unplug_after: int | None = None  # commands still answered before the port vanishes


class NXTEmulator:
    """A simulated brick serving a pty. `port` is the device path for the driver (the
    `link` symlink when given, a stable name like /dev/rfcomm0). Use as a context manager
    or call `close()`. `received` holds every frame the brick got, header included."""

    def __init__(self, config: EmulatorConfig = EmulatorConfig(), camera_dir: str | Path | None = None,
                 link: str | Path | None = None, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)):
        self.config = config
        self.camera_dir = Path(camera_dir) if camera_dir else None
        self.link = Path(link) if link else None
        self.pose = np.array(pose, dtype=np.float64)
        self.motors = [_Motor() for _ in range(3)]
        self.inputs = [(0, 0)] * 4  # (type, mode) per sensor port
        self.bumps = [False, False]  # front, rear pressed
        self.shots = 0
        self.received: list[bytes] = []
        self.faults = _Faults()
        self.lock = threading.RLock()
        self._i2c = [None] * 4  # pending (bytes, polls left) per port
        self._stop = threading.Event()
        self._fds = None
        self._clock = time.monotonic()
        self.plugged = False
        self.replug()
        self._thread = threading.Thread(target=self._serve, daemon=True, name="nxt-emulator")
        self._thread.start()

    # --- the port -----------------------------------------------------------------
    @property
    def port(self) -> str:
        return str(self.link) if self.link else self._pty_name

    def replug(self) -> None:
        """(Re)create the pty; with a `link`, point it at the new device."""
        with self.lock:
            master, slave = os.openpty()
            tty.setraw(slave)
            tty.setraw(master)
            self._pty_name = os.ttyname(slave)
            self._fds = (master, slave)
            if self.link:
                tmp = self.link.with_name(self.link.name + ".new")
                tmp.unlink(missing_ok=True)
                tmp.symlink_to(self._pty_name)
                os.replace(tmp, self.link)
            self.plugged = True

    def unplug(self) -> None:
        """The port disappears (Bluetooth link lost): the pty closes, the link goes. The
        brick itself keeps running its motors until their tacho limits, as the real one."""
        with self.lock:
            if not self.plugged:
                return
            self.plugged = False
            if self.link:
                self.link.unlink(missing_ok=True)
            for fd in self._fds:
                os.close(fd)
            self._fds = None

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.unplug()

    def __enter__(self) -> "NXTEmulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- faults -------------------------------------------------------------------
    def inject_garbage(self, data: bytes) -> None:
        """Write `data` before the next reply (line noise, a half-sent frame)."""
        with self.lock:
            self.faults.garbage += data

    def drop_replies(self, n: int = 1) -> None:
        """Swallow the next `n` replies (the driver must time out and retry)."""
        with self.lock:
            self.faults.drop += n

    def fail(self, opcode: int, status: int, times: int = 1) -> None:
        """Answer the next `times` commands `opcode` with error `status`."""
        with self.lock:
            self.faults.status[int(opcode)] = [status, times]

    def unplug_after(self, n_commands: int) -> None:
        """Unplug after answering `n_commands` more commands (mid-command loss)."""
        with self.lock:
            self.faults.unplug_after = n_commands

    # --- simulation ---------------------------------------------------------------
    def _serve(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            fds = self._fds
            with self.lock:
                self._advance_to_now()
            if fds is None:
                time.sleep(0.005)
                continue
            try:
                ready, _, _ = select.select([fds[0]], [], [], 0.005)
                if ready:
                    buf += os.read(fds[0], 4096)
            except OSError:
                time.sleep(0.005)  # unplugged under our feet
                continue
            while len(buf) >= 2:
                n = buf[0] | buf[1] << 8
                if len(buf) < 2 + n:
                    break
                frame, tgram = bytes(buf[:2 + n]), bytes(buf[2:2 + n])
                del buf[:2 + n]
                self._handle(frame, tgram)

    def _advance_to_now(self) -> None:
        now = time.monotonic()
        self._advance((now - self._clock) * self.config.time_scale)
        self._clock = now

    def _handle(self, frame: bytes, tgram: bytes) -> None:
        with self.lock:
            self._advance_to_now()  # the world moves on continuously between commands
            self.received.append(frame)
            if len(tgram) < 2:
                return
            reply = self._execute(tgram)
            f = self.faults
            if reply is not None and not tgram[0] & P.TYPE_NO_REPLY:
                if f.drop:
                    f.drop -= 1
                else:
                    time.sleep(self.config.reply_latency_s)
                    self._write(f.garbage + P.frame(reply))
                    f.garbage = b""
            if f.unplug_after is not None:
                f.unplug_after -= 1
                if f.unplug_after <= 0:
                    f.unplug_after = None
                    self.unplug()

    def _write(self, data: bytes) -> None:
        if self._fds is not None:
            try:
                os.write(self._fds[0], data)
            except OSError:
                pass

    def _advance(self, dt: float) -> None:
        """Turn the running motors for `dt` simulated seconds, moving the robot."""
        if dt <= 0:
            return
        c = self.config
        deg = np.array([m.power / 100 * c.full_speed_deg_s * dt if m.running else 0.0 for m in self.motors])
        for i, m in enumerate(self.motors):
            if m.running and m.tacho_limit:
                deg[i] = np.sign(deg[i]) * min(abs(deg[i]), m.tacho_limit - abs(m.tacho))
        # sync regulation holds a pair together: a synced motor waits for its partner
        synced = [i for i, m in enumerate(self.motors) if m.running and m.regulation == P.REGULATION_SYNC]
        step = min(abs(deg[i]) for i in synced) if len(synced) == 2 else 0.0
        for i in synced:
            deg[i] = np.sign(deg[i]) * step
        frac = self._free_fraction(np.radians(deg[1:]) * c.wheel_radius_m)
        deg[1:] *= frac  # against a wall the wheels stop (blocked)
        self.pose = self._moved(np.radians(deg[1:]) * c.wheel_radius_m)
        self.bumps = [self._touching(1.0), self._touching(-1.0)]
        for i, m in enumerate(self.motors):
            m.tacho += deg[i]
            m.block_tacho += deg[i]
            m.rotation += deg[i]
            if m.running and m.tacho_limit and abs(m.tacho) >= m.tacho_limit - 1e-6:
                for j in (synced if i in synced else [i]):  # a synced pair stops together
                    self.motors[j].power, self.motors[j].run_state = 0, P.RUN_IDLE
        if self.motors[0].running and not self._shutter_down:
            self._fire_shutter()
        self._shutter_down = self.motors[0].running

    _shutter_down = False

    def _moved(self, wheels_m: np.ndarray) -> np.ndarray:
        """The pose after the wheels roll (left, right) metres (midpoint integration)."""
        ds, dth = (wheels_m[0] + wheels_m[1]) / 2, (wheels_m[1] - wheels_m[0]) / self.config.track_m
        th = self.pose[2] + dth / 2
        return self.pose + [ds * np.cos(th), ds * np.sin(th), dth]

    def _inside(self, pose: np.ndarray, margin: float = 0.0) -> bool:
        hx, hy = np.subtract(self.config.room_half_size_m, self.config.robot_radius_m + margin)
        return abs(pose[0]) <= hx and abs(pose[1]) <= hy

    def _free_fraction(self, wheels_m: np.ndarray) -> float:
        """Largest fraction of the wheel motion that keeps the robot off the walls."""
        if self._inside(self._moved(wheels_m)):
            return 1.0
        lo, hi = 0.0, 1.0
        for _ in range(20):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if self._inside(self._moved(wheels_m * mid)) else (lo, mid)
        return lo

    def _touching(self, direction: float, contact_m: float = 0.005) -> bool:
        """The bumper facing `direction` (+1 front, -1 rear) touches a wall."""
        th = self.pose[2]
        probe = self.pose + [direction * contact_m * np.cos(th), direction * contact_m * np.sin(th), 0.0]
        return not self._inside(probe)

    def _fire_shutter(self) -> None:
        """The camera takes a photo; it appears in `camera_dir` atomically (Eye-Fi)."""
        self.shots += 1
        if self.camera_dir is None:
            return
        import cv2

        w, h = self.config.image_size
        img = np.zeros((h, w, 3), np.uint8)
        img[..., 0] = (self.shots * 37) % 256
        img[..., 1] = np.arange(w, dtype=np.uint8)[None, :]
        img[..., 2] = np.arange(h, dtype=np.uint8)[:, None]
        path = self.camera_dir / f"IMG_{self.shots:04d}.png"
        tmp = self.camera_dir / f".IMG_{self.shots:04d}.tmp.png"
        cv2.imwrite(str(tmp), img[..., ::-1])
        os.replace(tmp, path)

    # --- sensors ------------------------------------------------------------------
    def range_cm(self) -> int:
        """Ultrasonic: distance along the heading to the room's wall (cm, 255 = none)."""
        x, y, th = self.pose
        hx, hy = self.config.room_half_size_m
        c, s = np.cos(th), np.sin(th)
        ts = [t for t in ((hx - x) / c if c > 1e-9 else np.inf, (-hx - x) / c if c < -1e-9 else np.inf,
                          (hy - y) / s if s > 1e-9 else np.inf, (-hy - y) / s if s < -1e-9 else np.inf)]
        return int(min(255, round(min(ts) * 100)))

    def heading_deg(self) -> int:
        """HiTechnic compass: degrees clockwise from north, 0..359."""
        return int(round(np.degrees(self.config.north_rad - self.pose[2]))) % 360

    def _registers(self, port: int) -> bytes:
        """The I2C register file of the sensor on `port` (address -> byte)."""
        reg = bytearray(0x50)
        if port == 2:  # LEGO ultrasonic
            reg[0x00:0x08], reg[0x08:0x10], reg[0x10:0x18] = b"V1.0\0\0\0\0", b"LEGO\0\0\0\0", b"Sonar\0\0\0"
            reg[0x42] = self.range_cm()
        elif port == 3:  # HiTechnic compass
            reg[0x00:0x08], reg[0x08:0x10], reg[0x10:0x18] = b"\xfdV2.1   ", b"HITECHNC", b"Compass "
            h = self.heading_deg()
            reg[0x42], reg[0x43] = h // 2, h % 2
        return bytes(reg)

    # --- commands -----------------------------------------------------------------
    def _execute(self, tgram: bytes) -> bytes | None:
        """The reply telegram to a command telegram (None: no reply at all)."""
        op, args = tgram[1], tgram[2:]
        fail = self.faults.status.get(op)
        if fail:
            fail[1] -= 1
            if fail[1] <= 0:
                del self.faults.status[op]
            return self._reply(op, fail[0])
        try:
            opcode = P.Opcode(op)
        except ValueError:
            return bytes((P.TYPE_REPLY, op, 0xBE))
        try:
            return self._reply(op, 0, getattr(self, "_do_" + opcode.name.lower())(args))
        except (struct.error, IndexError):
            return self._reply(op, 0xBF)  # insane packet
        except _Status as e:
            return self._reply(op, e.status)

    @staticmethod
    def _reply(op: int, status: int, values: bytes = b"") -> bytes:
        if status:
            values = bytes(P.REPLY_LENGTH[P.Opcode(op)] - 3)  # full length, zeros
        return bytes((P.TYPE_REPLY, op, status)) + values

    def _motor_ports(self, port: int) -> list[int]:
        if port == 0xFF:
            return [0, 1, 2]
        if port > 2:
            raise _Status(0xF0)
        return [port]

    def _do_set_output_state(self, args: bytes) -> bytes:
        port, power, mode, reg, turn, run, limit = struct.unpack("<BbBBbBI", args)
        if not -100 <= power <= 100:
            raise _Status(0xC0)
        for p in self._motor_ports(port):
            m = self.motors[p]
            m.power, m.mode, m.regulation, m.turn_ratio, m.run_state = power, mode, reg, turn, run
            m.tacho_limit, m.tacho = limit, 0.0
        return b""

    def _do_get_output_state(self, args: bytes) -> bytes:
        (port,) = self._motor_ports(args[0])
        m = self.motors[port]
        return struct.pack("<BbBBbBIiii", port, m.power, m.mode, m.regulation, m.turn_ratio, m.run_state,
                           m.tacho_limit, round(m.tacho), round(m.block_tacho), round(m.rotation))

    def _do_set_input_mode(self, args: bytes) -> bytes:
        port, typ, mode = struct.unpack("<BBB", args)
        self._sensor_port(port)
        self.inputs[port] = (typ, mode)
        return b""

    def _sensor_port(self, port: int) -> int:
        if port > 3:
            raise _Status(0xF0)
        return port

    def _do_get_input_values(self, args: bytes) -> bytes:
        port = self._sensor_port(args[0])
        typ, mode = self.inputs[port]
        pressed = port < 2 and self.bumps[port] and typ == P.SENSOR_SWITCH
        raw = 183 if pressed else 1023
        return struct.pack("<B??BBHHhh", port, typ != 0, False, typ, mode, raw, raw, int(pressed), int(pressed))

    def _do_reset_motor_position(self, args: bytes) -> bytes:
        port, relative = struct.unpack("<B?", args)
        for p in self._motor_ports(port):
            if relative:
                self.motors[p].block_tacho = 0.0
            else:
                self.motors[p].rotation = 0.0
        return b""

    def _do_get_battery_level(self, args: bytes) -> bytes:
        return struct.pack("<H", self.config.battery_mv)

    def _do_keep_alive(self, args: bytes) -> bytes:
        return struct.pack("<I", self.config.sleep_timeout_ms)

    def _do_ls_write(self, args: bytes) -> bytes:
        port, tx_len, rx_len = args[0], args[1], args[2]
        tx = args[3:3 + tx_len]
        if len(tx) != tx_len or tx_len < 2 or rx_len > 16:
            raise _Status(0xED)
        if self.inputs[self._sensor_port(port)][0] != P.SENSOR_LOW_SPEED_9V or port < 2:
            raise _Status(0xE0)  # not configured as I2C, or nothing there
        if tx[0] != P.I2C_DEVICE:
            raise _Status(0xDD)  # nobody acknowledges that address
        reg = self._registers(port)
        self._i2c[port] = (reg[tx[1]:tx[1] + rx_len], self.config.i2c_pending_polls)
        return b""

    def _do_ls_get_status(self, args: bytes) -> bytes:
        port = self._sensor_port(args[0])
        pending = self._i2c[port]
        if pending is None:
            return b"\x00"
        data, polls = pending
        if polls > 0:
            self._i2c[port] = (data, polls - 1)
            raise _Status(P.STATUS_PENDING)
        return bytes((len(data),))

    def _do_ls_read(self, args: bytes) -> bytes:
        port = self._sensor_port(args[0])
        pending = self._i2c[port]
        if pending is None or pending[1] > 0:
            raise _Status(P.STATUS_PENDING if pending else 0xE0)
        self._i2c[port] = None
        data = pending[0]
        return bytes((len(data),)) + data + bytes(16 - len(data))


class _Status(Exception):
    def __init__(self, status: int):
        self.status = status
