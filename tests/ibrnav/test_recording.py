"""Every command's recording carries its blueprint and the command line that made it: a few
cheap commands are run as a user types them, and their `.rrd` files are read back with
rerun's chunk reader."""

from __future__ import annotations

import shlex
import subprocess
import sys

import pytest

from ibrnav.recording import analysis_blueprint, blueprint_for, recording_layout, recording_scalars

CHEAP = {
    "drive": (["drive", "--max-legs", "1", "--width", "32", "--height", "24"],
              {("3D", "world", "world"), ("2D", "observed", "world/robot/camera"), ("TimeSeries", "error", "plots")},
              {"plots/estimate_error_m": 1}),
    "eval-track": (["eval-track", "--trials", "1", "--steps", "2", "--particles", "50"],
                   {("3D", "world", "world"), ("2D", "observed", "localization/observed"),
                    ("2D", "rendered", "localization/rendered_at_estimate"), ("TimeSeries", "particles", "plots")},
                   {"plots/particles": 2, "plots/estimate_error_m": 2}),
    "vueplan": (["vueplan", "synthetic:office", "--phase1-only", "--candidates", "30"],
                {("3D", "world", "world"), ("TimeSeries", "coverage", "plots")}, {}),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CHEAP))
def test_a_commands_recording_has_its_blueprint_and_command_line(name, tmp_path):
    argv, expected_views, expected_plots = CHEAP[name]
    rrd = tmp_path / f"{name}.rrd"
    run = subprocess.run([sys.executable, "-m", "ibrnav", "-q", *argv, "--save", str(rrd)], capture_output=True,
                         text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    layout = recording_layout(str(rrd))
    assert layout["application_id"] == f"ibrnav_{name.replace('-', '_')}"
    assert expected_views <= set(layout["views"]), layout["views"]
    assert ("TextDocument", "command", "meta/command") in layout["views"]
    first_line = layout["command"].splitlines()[0]
    assert shlex.split(first_line) == ["ibrnav", "-q", *argv, "--save", str(rrd)]
    assert "ibrnav " in layout["command"].splitlines()[-1]  # the version line
    if expected_plots:  # the time series, read back with rerun's dataframe API
        plots = recording_scalars(str(rrd))
        for plot, n_steps in expected_plots.items():
            assert plots[plot].notna().sum() == n_steps, plots


def test_every_command_gets_a_blueprint_with_the_world_and_the_command():
    from ibrnav.cli import COMMANDS

    for app_id in [f"ibrnav_{c.replace('-', '_')}" for c in COMMANDS] + ["ibrnav_explore_random"]:
        bp = blueprint_for(app_id)
        assert bp.root_container is not None, app_id
    mission, plain = blueprint_for("ibrnav_demo"), analysis_blueprint()
    assert repr(mission) != repr(plain)  # the mission's has the photo and the render


def test_a_file_without_a_recording_is_named(tmp_path):
    bad = tmp_path / "empty.rrd"
    bad.write_bytes(b"")
    with pytest.raises(Exception, match="empty.rrd"):
        recording_layout(str(bad))
