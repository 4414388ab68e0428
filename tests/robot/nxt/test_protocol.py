"""NXT telegrams checked byte for byte against nxt-python (an independent encoder), and the
reply parser fuzzed with hypothesis."""

import struct
import time

import nxt.error
import nxt.motor
import nxt.sensor
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nxt.backend.devfile import DevFileSock
from nxt.telegram import CODES, Opcode as NxtOpcode, Telegram

from ibr.errors import InputError
from robot.nxt import protocol as P
from robot.nxt.emulator import NXTEmulator

M, S = nxt.motor, nxt.sensor

# (our telegram, how nxt-python sends the same command)
CASES = [
    (P.set_output_state(1, 60, 0x07, 2, 0, 0x20, 1023, reply=False),
     lambda b: b.set_output_state(M.Port.B, 60, M.Mode.ON | M.Mode.BRAKE | M.Mode.REGULATED,
                                  M.RegulationMode.SYNC, 0, M.RunState.RUNNING, 1023)),
    (P.set_output_state(2, -40, 0x05, 1, -50, 0x20, 70000, reply=False),
     lambda b: b.set_output_state(M.Port.C, -40, M.Mode.ON | M.Mode.REGULATED, M.RegulationMode.SPEED,
                                  -50, M.RunState.RUNNING, 70000)),
    (P.set_output_state(0, 0, 0, 0, 0, 0, 0, reply=False),
     lambda b: b.set_output_state(M.Port.A, 0, M.Mode.IDLE, M.RegulationMode.IDLE, 0, M.RunState.IDLE, 0)),
    (P.set_input_mode(0, P.SENSOR_SWITCH, P.SENSOR_MODE_BOOL, reply=False),
     lambda b: b.set_input_mode(S.Port.S1, S.Type.SWITCH, S.Mode.BOOL)),
    (P.set_input_mode(3, P.SENSOR_LOW_SPEED_9V, P.SENSOR_MODE_RAW, reply=False),
     lambda b: b.set_input_mode(S.Port.S4, S.Type.LOW_SPEED_9V, S.Mode.RAW)),
    (P.get_output_state(2), lambda b: b.get_output_state(M.Port.C)),
    (P.get_input_values(1), lambda b: b.get_input_values(S.Port.S2)),
    (P.reset_motor_position(1, False), lambda b: b.reset_motor_position(M.Port.B, False)),
    (P.reset_motor_position(2, True), lambda b: b.reset_motor_position(M.Port.C, True)),
    (P.get_battery_level(), lambda b: b.get_battery_level()),
    (P.keep_alive(), lambda b: b.keep_alive()),
    (P.ls_write(2, bytes((0x02, 0x42)), 1), lambda b: b.ls_write(S.Port.S3, bytes((0x02, 0x42)), 1)),
    (P.ls_get_status(3), lambda b: b.ls_get_status(S.Port.S4)),
    (P.ls_read(2), lambda b: b.ls_read(S.Port.S3)),
]


@pytest.fixture()
def emulator_and_nxt_python():
    with NXTEmulator() as emu:
        brick = DevFileSock(emu.port).connect()  # nxt-python's own Bluetooth device-file backend
        yield emu, brick
        brick.close()


def test_command_frames_equal_nxt_python(emulator_and_nxt_python):
    emu, brick = emulator_and_nxt_python
    brick.set_input_mode(S.Port.S3, S.Type.LOW_SPEED_9V, S.Mode.RAW)  # so LS commands are legal
    _wait_for(lambda: len(emu.received) == 1)
    for ours, theirs in CASES:
        n = len(emu.received)
        try:
            theirs(brick)
        except nxt.error.DirectProtocolError:
            pass  # e.g. I2C pending: only the frame sent matters here
        _wait_for(lambda: len(emu.received) > n)  # a no-reply command returns before it arrives
        assert emu.received[n] == P.frame(ours), theirs
        if ours[0] == P.TYPE_NO_REPLY:  # the same command asking for a reply differs in the type byte only
            assert P.frame(bytes((P.TYPE_DIRECT,)) + ours[1:])[3:] == emu.received[n][3:]


def test_replies_parse_as_nxt_python_parses_them(emulator_and_nxt_python):
    emu, brick = emulator_and_nxt_python
    emu.motors[1].rotation, emu.motors[1].power, emu.motors[1].tacho = -1234.0, -35, 77.0
    theirs = brick.get_output_state(M.Port.B)
    emu.motors[1].power = -35  # (unchanged: nothing runs)
    ours = P.parse_output_state(P.check_reply(_roundtrip(emu, P.get_output_state(1)), P.Opcode.GET_OUTPUT_STATE))
    assert (ours.port, ours.power, ours.tacho_count, ours.rotation_count) == \
        (theirs[0].value, theirs[1], theirs[7], theirs[9])
    assert P.parse_battery(P.check_reply(_roundtrip(emu, P.get_battery_level()), P.Opcode.GET_BATTERY_LEVEL)) \
        == brick.get_battery_level() == 7800


def _wait_for(condition, timeout_s=2.0):
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.002)


def _roundtrip(emu, tgram):
    """Ask the emulator directly (its command handler) for the reply telegram."""
    return emu._execute(tgram)


# --- fuzzing ----------------------------------------------------------------------
OPCODES = list(P.REPLY_LENGTH)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(OPCODES), st.binary(max_size=40))
def test_check_reply_never_crashes(opcode, data):
    try:
        values = P.check_reply(data, opcode)
    except P.NXTError as e:
        assert isinstance(e, InputError) and str(e)
        return
    assert data[:3] == bytes((2, opcode, 0)) and len(data) == P.REPLY_LENGTH[opcode]
    assert values == data[3:]


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=22, max_size=22), st.integers(0, 255))
def test_output_state_values_match_nxt_telegram(values, status):
    tgram = bytes((2, P.Opcode.GET_OUTPUT_STATE, status)) + values
    theirs = Telegram(NxtOpcode.DIRECT_GET_OUT_STATE, pkt=tgram)
    try:
        theirs.check_status()
        their_error = None
    except nxt.error.ProtocolError as e:
        their_error = e
    try:
        ours = P.parse_output_state(P.check_reply(tgram, P.Opcode.GET_OUTPUT_STATE))
    except P.NXTStatusError as e:
        assert their_error is not None and e.status == status
        if status in P.STATUS_MESSAGES:  # direct-command codes (the system ones are not ours)
            assert str(CODES[status]) in str(e)  # the same firmware message
        return
    assert their_error is None
    fields = [theirs.parse_u8(), theirs.parse_s8(), theirs.parse_u8(), theirs.parse_u8(), theirs.parse_s8(),
              theirs.parse_u8(), theirs.parse_u32(), theirs.parse_s32(), theirs.parse_s32(), theirs.parse_s32()]
    assert list(vars(ours).values()) == fields


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=60), st.binary(min_size=1, max_size=1), st.lists(st.integers(1, 8), max_size=10))
def test_reader_resyncs_after_garbage(garbage, level, cuts):
    garbage = garbage.replace(b"\x02", b"\x03")  # no byte of it can start a reply
    reply = bytes((2, P.Opcode.GET_BATTERY_LEVEL, 0)) + level + b"\x1e"
    stream = garbage + P.frame(reply) + garbage
    reader, pos, got = P.FrameReader(), 0, None
    for n in cuts + [len(stream)]:  # arbitrary chunking, as reads return
        reader.feed(stream[pos:pos + n])
        pos += n
        got = got or reader.next_reply(P.Opcode.GET_BATTERY_LEVEL)
    assert got == reply
    assert reader.discarded >= len(garbage)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=80))
def test_reader_only_returns_well_formed_replies(stream):
    reader = P.FrameReader()
    reader.feed(stream)
    got = reader.next_reply(P.Opcode.GET_OUTPUT_STATE)
    if got is not None:
        assert got[:2] == bytes((2, P.Opcode.GET_OUTPUT_STATE)) and len(got) in (25, 3)
        assert got in stream
        assert len(got) == 25 or got[2] != 0


def test_status_error_names_the_firmware_code():
    with pytest.raises(P.NXTStatusError, match="communication bus error") as e:
        P.check_reply(bytes((2, P.Opcode.LS_READ, 0xDD)) + bytes(17), P.Opcode.LS_READ)
    assert isinstance(e.value, InputError)
    with pytest.raises(P.NXTError, match="echoes GET_BATTERY_LEVEL"):
        P.check_reply(bytes((2, P.Opcode.GET_BATTERY_LEVEL, 0, 0, 0)), P.Opcode.KEEP_ALIVE)
    with pytest.raises(P.NXTError, match="not an NXT reply"):
        P.check_reply(bytes((1, P.Opcode.KEEP_ALIVE, 0, 0, 0, 0, 0)), P.Opcode.KEEP_ALIVE)
    assert struct.unpack("<H", P.frame(b"\x00\x0b")[:2])[0] == 2
