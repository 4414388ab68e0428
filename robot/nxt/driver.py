"""The NXT robot of Foster, Wang & Grupen (mobile robot for scene capture, section III),
driven from the host over the brick's Bluetooth serial port (pyserial).

Three layers: `NXTLink` moves frames over the port (timeouts, retries, reconnect when the
port disappears, resynchronisation after garbage); `NXTBrick` speaks the direct commands
(`robot.nxt.protocol`); `NXTRobot` is the robot (implements `robot.protocol.Robot`): a
differential drive on motors B (left) and C (right) with odometry from their rotation
counts, touch bumpers, the LEGO ultrasonic and HiTechnic compass on I2C, and the camera
shutter on motor port A. Every motion is sent with a tacho limit, so the brick stops the
wheels itself even if the link dies mid-command; the host also stops them on every exit
path (`with NXTRobot(...)`, an exception inside a motion, interpreter exit).
Frames: odometry poses (x, y, theta) in the robot's start frame, metres and radians.
"""

from __future__ import annotations

import atexit
import time
import weakref
from dataclasses import dataclass, field

import numpy as np
import serial

from ibr.camera import intrinsics_from_fov
from ibr.errors import InputError
from robot.nxt import protocol as P
from robot.protocol import MotionResult, Photo, check_motion, forward_camera_mount


try:
    import termios
    LINK_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
    """What a lost serial link raises: pyserial's error, the OS's, and on POSIX termios's (its
    `tcflush` of a port that vanished mid-command raises termios.error, not an OSError)."""
except ImportError:  # not POSIX
    LINK_ERRORS = (serial.SerialException, OSError)


class RobotConnectionError(InputError):
    """The robot's port does not exist, is not an NXT, or was lost; names the port."""


@dataclass(frozen=True)
class LinkConfig:
    timeout_s: float = 0.5
    """How long to wait for one reply (s)."""
    retries: int = 3
    """Extra attempts after a reply times out."""
    reconnect_s: float = 3.0
    """How long to keep trying to reopen a port that disappeared (s)."""
    reconnect_interval_s: float = 0.1
    """Pause between reopen attempts (s)."""
    baudrate: int = 115200
    """Serial speed (Bluetooth rfcomm ignores it)."""


class NXTLink:
    """Frames over a serial port (`port`: a device path or a pyserial URL)."""

    def __init__(self, port: str, config: LinkConfig = LinkConfig()):
        self.port, self.config = port, config
        self.reader = P.FrameReader()
        self.serial = None
        self.reconnects = 0
        self._open()

    def _open(self) -> None:
        try:
            self.serial = serial.serial_for_url(self.port, baudrate=self.config.baudrate, timeout=0.02,
                                                write_timeout=self.config.timeout_s)
        except (serial.SerialException, OSError, ValueError) as e:
            raise RobotConnectionError(f"{self.port}: cannot open the robot's serial port ({e})") from None

    def close(self) -> None:
        if self.serial is not None:
            try:
                self.serial.close()
            except LINK_ERRORS:
                pass
            self.serial = None

    def reconnect(self) -> None:
        """Reopen the port until it comes back or `reconnect_s` passes."""
        self.close()
        deadline = time.monotonic() + self.config.reconnect_s
        while True:
            try:
                self._open()
                self.reconnects += 1
                self.reader = P.FrameReader()
                return
            except RobotConnectionError as e:
                if time.monotonic() > deadline:
                    raise RobotConnectionError(f"{self.port}: lost the connection to the NXT and could not "
                                               f"reconnect within {self.config.reconnect_s:.1f} s ({e})") from None
            time.sleep(self.config.reconnect_interval_s)

    def command(self, tgram: bytes) -> bytes | None:
        """Send a command telegram; return its reply's values (None when no reply was
        asked for). Retries on timeout and after reconnecting; raises NXTStatusError for an
        error status, RobotConnectionError when the brick stays silent or gone."""
        opcode, want_reply = tgram[1], not tgram[0] & P.TYPE_NO_REPLY
        for attempt in range(self.config.retries + 1):
            try:
                if self.serial is None:
                    self.reconnect()
                self.serial.reset_input_buffer()  # stale replies to timed-out commands
                self.reader = P.FrameReader()
                self.serial.write(P.frame(tgram))
                if not want_reply:
                    return None
                reply = self._await(opcode)
            except LINK_ERRORS:
                self.reconnect()
                continue
            if reply is not None:
                return P.check_reply(reply, opcode)
        raise RobotConnectionError(
            f"{self.port}: no valid reply to {P.Opcode(opcode).name} after {self.config.retries + 1} tries "
            "(is an NXT brick on this port, switched on and paired?)")

    def _await(self, opcode: int) -> bytes | None:
        deadline = time.monotonic() + self.config.timeout_s
        while time.monotonic() < deadline:
            data = self.serial.read(max(1, self.serial.in_waiting))
            if data:
                self.reader.feed(data)
            reply = self.reader.next_reply(opcode)
            if reply is not None:
                return reply
        return None


class NXTBrick:
    """Direct commands on an `NXTLink`. Ports: motors 0-2 (A-C), sensors 0-3 (1-4)."""

    def __init__(self, link: NXTLink, confirm_writes: bool = True):
        self.link = link
        self.confirm = confirm_writes  # ask for a reply to SETOUTPUTSTATE / SETINPUTMODE

    def set_output_state(self, port: int, power: int, mode: int, regulation: int, turn_ratio: int,
                         run_state: int, tacho_limit: int) -> None:
        self.link.command(P.set_output_state(port, power, mode, regulation, turn_ratio, run_state,
                                             tacho_limit, self.confirm))

    def start_motors(self, states: list[tuple[int, int, int, int, int, int, int]]) -> None:
        """SETOUTPUTSTATE for several motors, each (port, power, mode, regulation,
        turn_ratio, run_state, tacho_limit), sent back to back: only the last asks for a
        reply (when `confirm`), so the brick starts them a frame's transmission apart, not
        a round trip apart (tens of ms over Bluetooth, in which the first wheel alone would
        pivot the robot about the still one)."""
        for i, state in enumerate(states):
            self.link.command(P.set_output_state(*state, self.confirm and i == len(states) - 1))

    def get_output_state(self, port: int) -> P.OutputState:
        return P.parse_output_state(self.link.command(P.get_output_state(port)))

    def set_input_mode(self, port: int, sensor_type: int, sensor_mode: int) -> None:
        self.link.command(P.set_input_mode(port, sensor_type, sensor_mode, self.confirm))

    def get_input_values(self, port: int) -> P.InputValues:
        return P.parse_input_values(self.link.command(P.get_input_values(port)))

    def reset_motor_position(self, port: int, relative: bool) -> None:
        self.link.command(P.reset_motor_position(port, relative))

    def battery_mv(self) -> int:
        return P.parse_battery(self.link.command(P.get_battery_level()))

    def keep_alive(self) -> int:
        return P.parse_keep_alive(self.link.command(P.keep_alive()))

    def i2c_read(self, port: int, register: int, n: int, tries: int = 3, polls: int = 30) -> bytes:
        """Read `n` bytes from `register` of the I2C sensor on `port`: LSWRITE, poll
        LSGETSTATUS while the bus is pending, LSREAD. Bus errors are retried `tries` times."""
        for attempt in range(tries):
            try:
                self.link.command(P.ls_write(port, bytes((P.I2C_DEVICE, register)), n))
                for _ in range(polls):
                    try:
                        if P.parse_ls_status(self.link.command(P.ls_get_status(port))) >= n:
                            break
                    except P.NXTStatusError as e:
                        if e.status != P.STATUS_PENDING:
                            raise
                data = P.parse_ls_read(self.link.command(P.ls_read(port)))
                if len(data) >= n:
                    return data[-n:]
            except P.NXTStatusError as e:
                if attempt == tries - 1:
                    raise P.NXTError(f"{self.link.port}: I2C sensor on port {port + 1} does not answer ({e})") \
                        from None
        raise P.NXTError(f"{self.link.port}: I2C sensor on port {port + 1} returned too few bytes")

    def brake(self, port: int) -> None:
        """Stop a motor and hold it (power 0, braked, speed-regulated)."""
        self.set_output_state(port, 0, P.MODE_ON | P.MODE_BRAKE | P.MODE_REGULATED, P.REGULATION_SPEED,
                              0, P.RUN_RUNNING, 0)

    def coast(self, port: int) -> None:
        """Switch a motor port off (no power, floating)."""
        self.set_output_state(port, 0, 0, P.REGULATION_IDLE, 0, P.RUN_IDLE, 0)


@dataclass(frozen=True)
class NXTRobotConfig:
    left_motor: int = 1
    """Output port of the left wheel (1 = B)."""
    right_motor: int = 2
    """Output port of the right wheel (2 = C)."""
    shutter_motor: int = 0
    """Output port wired to the camera's USB 5 V line (0 = A)."""
    front_bumper: int = 0
    """Sensor port of the front touch sensor (0 = port 1)."""
    rear_bumper: int = 1
    """Sensor port of the rear touch sensor."""
    ultrasonic: int = 2
    """Sensor port of the LEGO ultrasonic sensor (I2C)."""
    compass: int = 3
    """Sensor port of the HiTechnic compass (I2C)."""
    wheel_radius_m: float = 0.028
    """Wheel radius (m)."""
    track_m: float = 0.12
    """Distance between the wheels (m)."""
    drive_power: int = 60
    """Motor power for straight drives (percent)."""
    turn_power: int = 40
    """Motor power for turns in place (percent)."""
    keep_alive_s: float = 60.0
    """Send KEEPALIVE when this long has passed since the last one, so the brick does not
    fall asleep during a long mission (s)."""
    shutter_pulse_s: float = 0.2
    """How long the shutter port is powered (s)."""
    poll_s: float = 0.02
    """Interval between tacho / bumper polls during a motion (s)."""
    stall_s: float = 0.5
    """No wheel progress for this long while powered means stalled (s)."""
    motion_timeout_s: float = 60.0
    """Longest a single drive or turn may take (s)."""
    photo_timeout_s: float = 15.0
    """Longest wait for the photo after a shutter trigger (s)."""
    north_rad: float = np.pi / 2
    """World angle of magnetic north: compass heading h (clockwise) is world angle north - h."""
    fov_x_rad: float = np.radians(50.0)
    """Horizontal field of view of the camera (rad)."""
    image_size: tuple[int, int] = (640, 480)
    """Camera image (width, height) in pixels."""
    camera_height_m: float = 0.3
    """Height of the camera centre above the floor (m)."""


@dataclass
class _Odometry:
    """Differential-drive dead reckoning from wheel rotation counts (degrees)."""

    radius: float
    track: float
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    counts: tuple[float, float] | None = None

    def update(self, left: float, right: float) -> np.ndarray:
        if self.counts is not None:
            dl, dr = np.radians([left - self.counts[0], right - self.counts[1]]) * self.radius
            ds, dth = (dl + dr) / 2, (dr - dl) / self.track
            th = self.pose[2] + dth / 2
            self.pose = self.pose + [ds * np.cos(th), ds * np.sin(th), dth]
            self.pose[2] = (self.pose[2] + np.pi) % (2 * np.pi) - np.pi
        self.counts = (left, right)
        return self.pose.copy()


class NXTRobot:
    """The NXT robot on `port` (e.g. /dev/rfcomm0); implements `robot.protocol.Robot`.
    `photos` is a `robot.photo_source` (None: capture() raises). Use as a context manager."""

    def __init__(self, port: str, config: NXTRobotConfig = NXTRobotConfig(), photos=None,
                 link_config: LinkConfig = LinkConfig()):
        self.config, self.photos = config, photos
        self.link = NXTLink(port, link_config)
        self.brick = NXTBrick(self.link)
        try:
            self.brick.keep_alive()
        except RobotConnectionError:
            self.link.close()
            raise RobotConnectionError(f"{port}: no NXT answers on this port (no valid reply to "
                                       "KEEP_ALIVE; is it the brick's Bluetooth serial port?)") from None
        c = config
        self.intrinsics = intrinsics_from_fov(np.degrees(c.fov_x_rad), *c.image_size)
        self.image_size = c.image_size
        self.cam_from_robot = forward_camera_mount(c.camera_height_m)
        self._odom = _Odometry(c.wheel_radius_m, c.track_m)
        self._t0 = self._last_keep_alive = time.monotonic()
        self._n_photos = 0
        self._closed = False
        self._setup()
        _live.add(self)

    def _setup(self) -> None:
        c, b = self.config, self.brick
        for port in (c.front_bumper, c.rear_bumper):
            b.set_input_mode(port, P.SENSOR_SWITCH, P.SENSOR_MODE_BOOL)
        for port in (c.ultrasonic, c.compass):
            b.set_input_mode(port, P.SENSOR_LOW_SPEED_9V, P.SENSOR_MODE_RAW)
        self.stop()
        for port in (c.left_motor, c.right_motor):
            b.reset_motor_position(port, relative=False)
        self._odom.counts = None
        self._read_odometry()

    # --- lifecycle ----------------------------------------------------------------
    def __enter__(self) -> "NXTRobot":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop the motors (best effort) and close the port."""
        if self._closed:
            return
        self._closed = True
        self._safe_stop()
        self.link.close()
        _live.discard(self)

    def _safe_stop(self) -> None:
        try:
            self.stop()
        except (InputError, *LINK_ERRORS):
            pass  # the link is gone; the brick's tacho limits stop the wheels

    def stop(self) -> None:
        """Brake both wheels and switch the shutter port off."""
        c = self.config
        self.brick.brake(c.left_motor)
        self.brick.brake(c.right_motor)
        self.brick.coast(c.shutter_motor)

    def battery_mv(self) -> int:
        return self.brick.battery_mv()

    # --- motion -------------------------------------------------------------------
    def drive(self, distance_m: float) -> MotionResult:
        """Drive straight `distance_m` (negative: backwards); stops on a bumper or stall."""
        check_motion("NXTRobot: drive distance_m", distance_m)
        deg = int(round(np.degrees(abs(distance_m) / self.config.wheel_radius_m)))
        sign = 1 if distance_m >= 0 else -1
        p = sign * self.config.drive_power
        return self._move(deg, p, p, P.REGULATION_SYNC, bumper=0 if sign > 0 else 1)

    def turn(self, angle_rad: float) -> MotionResult:
        """Turn in place by `angle_rad` (counter-clockwise positive)."""
        check_motion("NXTRobot: turn angle_rad", angle_rad)
        c = self.config
        deg = int(round(np.degrees(abs(angle_rad) * c.track_m / 2 / c.wheel_radius_m)))
        p = (1 if angle_rad >= 0 else -1) * c.turn_power
        return self._move(deg, -p, p, P.REGULATION_SPEED, bumper=None)

    def _keep_awake(self) -> None:
        if time.monotonic() - self._last_keep_alive > self.config.keep_alive_s:
            self.brick.keep_alive()
            self._last_keep_alive = time.monotonic()

    def _move(self, deg: int, left_power: int, right_power: int, regulation: int,
              bumper: int | None) -> MotionResult:
        self._keep_awake()
        before = self._read_odometry()
        hit = [False, False]
        stalled = False
        if deg > 0:
            try:
                hit, stalled = self._run(deg, left_power, right_power, regulation, bumper)
            except BaseException:
                self._safe_stop()
                raise
        after = self._odom.update(*self._settled_counts())
        delta = after - before
        delta[2] = (delta[2] + np.pi) % (2 * np.pi) - np.pi
        return MotionResult(delta, hit[0], hit[1], stalled)

    def _run(self, deg, left_power, right_power, regulation, bumper) -> tuple[list[bool], bool]:
        c, b = self.config, self.brick
        mode = P.MODE_ON | P.MODE_BRAKE | P.MODE_REGULATED
        start = self._counts()
        b.start_motors([(port, power, mode, regulation, 0, P.RUN_RUNNING, deg)
                        for port, power in ((c.left_motor, left_power), (c.right_motor, right_power))])
        t_start = last_progress_t = time.monotonic()
        last = start
        hit, stalled = [False, False], False
        while True:
            time.sleep(c.poll_s)
            *states, counts = self._wheel_states()
            self._odom.update(*counts)
            now = time.monotonic()
            done = all(abs(n - s) >= deg - 1.5 for n, s in zip(counts, start)) or \
                all(s.run_state == P.RUN_IDLE for s in states)
            if done:
                break
            if bumper is not None:
                hit = list(self.bumpers())
                if hit[bumper]:
                    break
            if counts != last:
                last, last_progress_t = counts, now
            elif now - last_progress_t > c.stall_s:
                stalled = True
                break
            if now - t_start > c.motion_timeout_s:
                stalled = True
                break
        self.stop()
        return hit, stalled

    # --- sensors ------------------------------------------------------------------
    def _wheel_states(self) -> tuple[P.OutputState, P.OutputState, tuple[float, float]]:
        """Both wheels' output states and their rotation counts (degrees) aligned in time:
        the left wheel is read before and after the right one and the two averaged, so a
        moving robot's counts are not skewed by the read latency (which odometry would
        take for a turn). Read again when the link reconnected in between (a gap)."""
        c = self.config
        for _ in range(3):
            reconnects = self.link.reconnects
            left0 = self.brick.get_output_state(c.left_motor)
            right = self.brick.get_output_state(c.right_motor)
            left1 = self.brick.get_output_state(c.left_motor)
            if self.link.reconnects == reconnects:
                break
        return left1, right, ((left0.rotation_count + left1.rotation_count) / 2, right.rotation_count)

    def _counts(self) -> tuple[float, float]:
        return self._wheel_states()[2]

    def _settled_counts(self, tries: int = 5) -> tuple[float, float]:
        """The wheels' counts once braked: read until two reads agree. A reply that came
        late to a timed-out poll (a slow link) can still be in flight and be taken for the
        answer to the next read; it holds older counts of the moving wheels, so the first
        read that repeats the one before it is the settled one."""
        last = self._counts()
        for _ in range(tries):
            now = self._counts()
            if now == last:
                break
            last = now
        return last

    def _read_odometry(self) -> np.ndarray:
        return self._odom.update(*self._counts())

    def odometry(self) -> np.ndarray:
        """Odometry pose (3,) in the start frame, from the wheels' rotation counts."""
        return self._read_odometry()

    def compass(self) -> float:
        """Heading (rad, world frame, counter-clockwise) from the HiTechnic compass."""
        two_deg, adder = self.brick.i2c_read(self.config.compass, 0x42, 2)
        heading = np.radians(2 * two_deg + adder)
        return float((self.config.north_rad - heading + np.pi) % (2 * np.pi) - np.pi)

    def ultrasonic(self) -> float:
        """Range (m) from the ultrasonic sensor; 2.55 when nothing echoes."""
        (cm,) = self.brick.i2c_read(self.config.ultrasonic, 0x42, 1)
        return cm / 100.0

    def bumpers(self) -> tuple[bool, bool]:
        """(front, rear) touch sensors pressed."""
        c = self.config
        return (self.brick.get_input_values(c.front_bumper).scaled != 0,
                self.brick.get_input_values(c.rear_bumper).scaled != 0)

    def time_s(self) -> float:
        """Sensor time: seconds since the robot connected."""
        return time.monotonic() - self._t0

    def capture(self) -> Photo:
        """Pulse the shutter port, then wait for the photo; readings taken at the trigger."""
        if self.photos is None:
            raise InputError("this NXTRobot has no photo source (a camera folder or capture device)")
        c, b = self.config, self.brick
        self._keep_awake()
        odom, heading, rng = self.odometry(), self.compass(), self.ultrasonic()
        self.photos.arm()
        t, wall = self.time_s(), time.time()
        b.set_output_state(c.shutter_motor, 100, P.MODE_ON, P.REGULATION_IDLE, 0, P.RUN_RUNNING, 0)
        try:
            time.sleep(c.shutter_pulse_s)
        finally:
            b.coast(c.shutter_motor)
        image, _ = self.photos.fetch(wall, c.photo_timeout_s)
        photo = Photo(image, t, odom, heading, rng, self._n_photos)
        self._n_photos += 1
        return photo


_live: "weakref.WeakSet[NXTRobot]" = weakref.WeakSet()


@atexit.register
def _stop_all_at_exit() -> None:
    """Motors off for every robot still open when the interpreter exits."""
    for robot in list(_live):
        robot.close()
