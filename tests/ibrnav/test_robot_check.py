"""`ibrnav robot check`: reports battery and sensors of the (emulated) NXT; a missing port
is one clear error line, no traceback."""

import pytest

from ibrnav.cli import main


@pytest.fixture()
def ibrnav():
    return main


def test_check_reports_battery_sensors_and_motor_pulse(ibrnav, capsys):
    assert ibrnav(["robot", "check", "--emulator", "--pulse-deg", "45"]) == 0
    out = capsys.readouterr().out
    assert "battery        7.80 V" in out
    assert "ultrasonic     2.00 m" in out and "compass        0 deg" in out
    assert out.count("turned +45 deg of 45 commanded") == 2


def test_check_on_a_missing_port_is_a_clear_error(ibrnav, capsys, tmp_path):
    assert ibrnav(["robot", "check", "--port", str(tmp_path / "rfcomm0")]) == 2
    err = capsys.readouterr().err
    assert "rfcomm0" in err and "cannot open" in err and "Traceback" not in err
