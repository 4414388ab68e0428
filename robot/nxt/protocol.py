"""LEGO Mindstorms NXT direct commands: telegram encoding and reply parsing, no I/O.

Foster, Wang & Grupen (mobile robot for scene capture, section III) drive an NXT brick
from the host over its Bluetooth serial link: motors, a compass and an ultrasonic sensor on
the I2C (low-speed) ports, touch bumpers, and a motor port switched on to fire the camera.
This module is the wire format of LEGO's "Bluetooth Developer Kit" direct commands:

    frame   = length (u16, little-endian, of the telegram) + telegram
    command = type (0x00 reply wanted, 0x80 no reply) + opcode + arguments
    reply   = 0x02 + opcode echo + status + values

All integers are little-endian. A reply's status byte is 0 on success, else one of the
firmware's error codes (`STATUS_MESSAGES`). `FrameReader` finds the expected reply in a
byte stream that may hold garbage or stale frames (resynchronising byte by byte).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from ibr.errors import InputError

TYPE_DIRECT = 0x00
TYPE_NO_REPLY = 0x80
TYPE_REPLY = 0x02


class Opcode(enum.IntEnum):
    """Direct-command opcodes used by the driver."""

    SET_OUTPUT_STATE = 0x04
    SET_INPUT_MODE = 0x05
    GET_OUTPUT_STATE = 0x06
    GET_INPUT_VALUES = 0x07
    RESET_MOTOR_POSITION = 0x0A
    GET_BATTERY_LEVEL = 0x0B
    KEEP_ALIVE = 0x0D
    LS_GET_STATUS = 0x0E
    LS_WRITE = 0x0F
    LS_READ = 0x10


# Length of the reply telegram (type, opcode, status, values) of each command.
REPLY_LENGTH = {
    Opcode.SET_OUTPUT_STATE: 3, Opcode.SET_INPUT_MODE: 3, Opcode.GET_OUTPUT_STATE: 25,
    Opcode.GET_INPUT_VALUES: 16, Opcode.RESET_MOTOR_POSITION: 3, Opcode.GET_BATTERY_LEVEL: 5,
    Opcode.KEEP_ALIVE: 7, Opcode.LS_GET_STATUS: 4, Opcode.LS_WRITE: 3, Opcode.LS_READ: 20,
}

# The firmware's status codes (LEGO Bluetooth Developer Kit, appendix 2).
STATUS_MESSAGES = {
    0x20: "pending communication transaction in progress",
    0x40: "specified mailbox queue is empty",
    0xBD: "request failed (i.e. specified file not found)",
    0xBE: "unknown command opcode",
    0xBF: "insane packet",
    0xC0: "data contains out-of-range values",
    0xDD: "communication bus error",
    0xDE: "no free memory in communication buffer",
    0xDF: "specified channel/connection is not valid",
    0xE0: "specified channel/connection not configured or busy",
    0xEC: "no active program",
    0xED: "illegal size specified",
    0xEE: "illegal mailbox queue ID specified",
    0xEF: "attempted to access invalid field of a structure",
    0xF0: "bad input or output specified",
    0xFB: "insufficient memory available",
    0xFF: "bad arguments",
}
STATUS_PENDING = 0x20

# Output (motor) modes, regulation modes and run states.
MODE_ON, MODE_BRAKE, MODE_REGULATED = 0x01, 0x02, 0x04
REGULATION_IDLE, REGULATION_SPEED, REGULATION_SYNC = 0, 1, 2
RUN_IDLE, RUN_RAMP_UP, RUN_RUNNING, RUN_RAMP_DOWN = 0x00, 0x10, 0x20, 0x40
# Sensor types and modes used here.
SENSOR_SWITCH, SENSOR_LOW_SPEED_9V = 0x01, 0x0B
SENSOR_MODE_RAW, SENSOR_MODE_BOOL = 0x00, 0x20
I2C_DEVICE = 0x02  # I2C bus address of the LEGO ultrasonic and the HiTechnic compass
MAX_TELEGRAM = 64  # Bluetooth telegrams are at most 64 bytes


class NXTError(InputError):
    """A reply from the brick that reports an error, or is not a valid NXT reply."""


class NXTStatusError(NXTError):
    """The brick answered with a non-zero status byte."""

    def __init__(self, opcode: int, status: int):
        self.opcode, self.status = opcode, status
        what = STATUS_MESSAGES.get(status, "unknown status code")
        super().__init__(f"NXT {_opname(opcode)} failed: status {status:#04x} ({what})")


def _opname(opcode: int) -> str:
    try:
        return Opcode(opcode).name
    except ValueError:
        return f"opcode {opcode:#04x}"


# --- commands ---------------------------------------------------------------------
def telegram(opcode: Opcode, args: bytes = b"", reply: bool = True) -> bytes:
    """A command telegram (no length header)."""
    return bytes((TYPE_DIRECT if reply else TYPE_NO_REPLY, int(opcode))) + args


def frame(tgram: bytes) -> bytes:
    """The Bluetooth frame: u16 little-endian length, then the telegram."""
    if not 0 < len(tgram) <= MAX_TELEGRAM:
        raise ValueError(f"telegram of {len(tgram)} bytes (1..{MAX_TELEGRAM})")
    return struct.pack("<H", len(tgram)) + tgram


def set_output_state(port: int, power: int, mode: int, regulation: int, turn_ratio: int,
                     run_state: int, tacho_limit: int, reply: bool = True) -> bytes:
    """SETOUTPUTSTATE: port 0-2 (A-C, 0xFF all), power -100..100, tacho_limit in degrees
    (0: run forever)."""
    return telegram(Opcode.SET_OUTPUT_STATE, struct.pack(
        "<BbBBbBI", port, power, mode, regulation, turn_ratio, run_state, tacho_limit), reply)


def get_output_state(port: int) -> bytes:
    return telegram(Opcode.GET_OUTPUT_STATE, bytes((port,)))


def set_input_mode(port: int, sensor_type: int, sensor_mode: int, reply: bool = True) -> bytes:
    """SETINPUTMODE: sensor port 0-3 (1-4 on the brick)."""
    return telegram(Opcode.SET_INPUT_MODE, bytes((port, sensor_type, sensor_mode)), reply)


def get_input_values(port: int) -> bytes:
    return telegram(Opcode.GET_INPUT_VALUES, bytes((port,)))


def reset_motor_position(port: int, relative: bool) -> bytes:
    return telegram(Opcode.RESET_MOTOR_POSITION, struct.pack("<B?", port, relative))


def get_battery_level() -> bytes:
    return telegram(Opcode.GET_BATTERY_LEVEL)


def keep_alive() -> bytes:
    return telegram(Opcode.KEEP_ALIVE)


def ls_write(port: int, tx: bytes, rx_len: int) -> bytes:
    """LSWRITE: send `tx` (I2C device address first) and expect `rx_len` bytes back."""
    if len(tx) > 16 or not 0 <= rx_len <= 16:
        raise ValueError("LSWRITE carries at most 16 bytes each way")
    return telegram(Opcode.LS_WRITE, bytes((port, len(tx), rx_len)) + tx)


def ls_get_status(port: int) -> bytes:
    return telegram(Opcode.LS_GET_STATUS, bytes((port,)))


def ls_read(port: int) -> bytes:
    return telegram(Opcode.LS_READ, bytes((port,)))


# --- replies ----------------------------------------------------------------------
@dataclass(frozen=True)
class OutputState:
    """GETOUTPUTSTATE reply. Counts in degrees: tacho_count since the last motion command,
    block_tacho_count since the last relative reset, rotation_count since the last
    absolute reset (what odometry integrates)."""

    port: int
    power: int
    mode: int
    regulation: int
    turn_ratio: int
    run_state: int
    tacho_limit: int
    tacho_count: int
    block_tacho_count: int
    rotation_count: int


@dataclass(frozen=True)
class InputValues:
    """GETINPUTVALUES reply; a touch sensor in BOOL mode reads scaled = 1 when pressed."""

    port: int
    valid: bool
    calibrated: bool
    sensor_type: int
    sensor_mode: int
    raw: int
    normalized: int
    scaled: int
    calibrated_value: int


def check_reply(tgram: bytes, opcode: int) -> bytes:
    """The values of a reply telegram to `opcode` (after type, echo and status), or
    NXTError / NXTStatusError naming what is wrong."""
    if len(tgram) < 3:
        raise NXTError(f"NXT reply of {len(tgram)} bytes to {_opname(opcode)} is too short")
    if tgram[0] != TYPE_REPLY:
        raise NXTError(f"not an NXT reply (type byte {tgram[0]:#04x}, expected 0x02)")
    if tgram[1] != opcode:
        raise NXTError(f"NXT reply echoes {_opname(tgram[1])}, expected {_opname(opcode)}")
    if tgram[2] != 0:
        raise NXTStatusError(opcode, tgram[2])
    want = REPLY_LENGTH.get(opcode, len(tgram))
    if len(tgram) != want:
        raise NXTError(f"NXT reply to {_opname(opcode)} has {len(tgram)} bytes, expected {want}")
    return tgram[3:]


def parse_output_state(values: bytes) -> OutputState:
    return OutputState(*struct.unpack("<BbBBbBIiii", values))


def parse_input_values(values: bytes) -> InputValues:
    return InputValues(*struct.unpack("<B??BBHHhh", values))


def parse_battery(values: bytes) -> int:
    """Battery voltage (mV)."""
    return struct.unpack("<H", values)[0]


def parse_keep_alive(values: bytes) -> int:
    """Sleep timeout (ms)."""
    return struct.unpack("<I", values)[0]


def parse_ls_status(values: bytes) -> int:
    """Bytes ready to read from the I2C device."""
    return values[0]


def parse_ls_read(values: bytes) -> bytes:
    """The data bytes of an LSREAD reply (count byte, then 16 bytes padded)."""
    n = values[0]
    if n > 16:
        raise NXTError(f"NXT LSREAD reply claims {n} bytes (at most 16)")
    return bytes(values[1:1 + n])


class FrameReader:
    """Accumulates bytes from the port and extracts reply telegrams.

    `next_reply(opcode)` returns the first well-formed reply frame to `opcode` in the
    buffer (length header matching the reply's length, or 3 for a short error reply; type
    0x02; the opcode echo) and drops every byte before it: garbage from a noisy link and
    stale replies to earlier commands are skipped, one byte at a time, so the reader
    resynchronises on the next real frame. Returns None while no such frame is complete."""

    def __init__(self):
        self.buffer = bytearray()
        self.discarded = 0  # bytes skipped so far (garbage or stale frames)

    def feed(self, data: bytes) -> None:
        self.buffer += data

    def next_reply(self, opcode: int) -> bytes | None:
        want = REPLY_LENGTH.get(opcode)
        buf, i = self.buffer, 0
        while i + 4 <= len(buf):
            n = buf[i] | buf[i + 1] << 8
            if (n == want or n == 3) and buf[i + 2] == TYPE_REPLY and buf[i + 3] == opcode:
                if i + 2 + n > len(buf):
                    break  # the frame is not complete yet
                tgram = bytes(buf[i + 2:i + 2 + n])
                if n == 3 and want != 3 and tgram[2] == 0:
                    i += 1  # a short reply must carry an error status
                    continue
                self._drop(i + 2 + n)
                self.discarded -= 2 + n
                return tgram
            i += 1
        self._drop(i)
        return None

    def _drop(self, n: int) -> None:
        self.discarded += n
        del self.buffer[:n]
