"""`ibrnav explore SCENE`: the SCENE spec is read like every other command's
(`synthetic:NAME[?seed=N]`), and a bad one is one line naming it, with no traceback."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


def ibrnav(*args):
    return subprocess.run([str(BIN / "ibrnav"), *map(str, args)], capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("spec", ["synthetic:nosuch?seed=3", "synthetic:office?seed=x", "synthetic:office?views=3"])
def test_a_bad_scene_spec_is_one_line_naming_it(spec):
    run = ibrnav("explore", spec)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and spec in run.stderr and "Traceback" not in run.stderr


def test_explore_runs_with_a_seeded_spec(tmp_path):
    out = tmp_path / "explore.json"
    run = ibrnav("explore", "synthetic:office?seed=3", "--strategy", "random", "--photos", 3, "--json", out,
                 "--achievable-poses", 0)
    assert run.returncode == 0, run.stderr
    report = json.loads(out.read_text())
    assert report["scene"] == "synthetic:office?seed=3" and report["photos"] == 3


def test_explore_in_an_apartment_reports_rooms_and_why_it_stopped(tmp_path):
    out = tmp_path / "explore.json"
    run = ibrnav("explore", "synthetic:apartment?seed=5", "--strategy", "random", "--photos", 4, "--json", out,
                 "--achievable-poses", 80)
    assert run.returncode == 0, run.stderr
    report = json.loads(out.read_text())
    assert report["stopped_because"] == "budget" and report["photos"] == 4
    assert len(report["rooms"]) >= 2 and len(report["rooms_visited"]) == 1  # 4 photos: one circle, one room
    assert set(report["rooms_visited"]) <= set(report["rooms"])
    assert report["localization_error_m"] is None and report["map_scale_error"] is None  # no adaptive stage, no map
    assert report["coverage"] <= report["achievable_coverage"] <= 1
