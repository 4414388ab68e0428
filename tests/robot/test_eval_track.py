import argparse
import json

import numpy as np
import pytest
from rerun.chunk import RrdReader

from ibr.errors import InputError
from robot import cli_eval_track as cli
from robot.eval_track import TrackConfig, run_tracking, steps_to_localise


def test_steps_to_localise_needs_a_held_fix():
    cfg = TrackConfig(recovered_m=0.25, recovered_rad=1.0, hold_steps=3)
    err = np.array([[1, 0], [0.1, 0], [0.5, 0], [0.1, 0], [0.1, 0], [0.1, 0], [2, 0]], float)
    assert steps_to_localise(err, 0, cfg) == 3
    assert steps_to_localise(err, 4, cfg) is None


def test_global_localisation_and_kidnap_recovery_in_the_office(office, gl_ctx):
    """From a uniform prior over the whole floor the filter finds the robot; teleported
    mid-run, it finds it again (augmented MCL's random injection)."""
    config = TrackConfig(steps=26, kidnap_step=10, n_particles=1500, n_max=3000)
    res = run_tracking(office, seed=3, config=config, ctx=gl_ctx)
    assert res["steps_to_converge"] is not None and res["steps_to_converge"] < 10
    assert res["median_tracking_error_m"] < 0.2
    assert res["error_m"][10] > 1.0  # the kidnapping really lost it
    assert res["steps_to_recover"] is not None


def _parse(argv):
    parser = argparse.ArgumentParser()
    cli.register(parser.add_subparsers(dest="command"))
    return parser.parse_args(argv)


def test_eval_track_cli_writes_json_and_the_rerun_entities(tmp_path, gl_ctx):
    """`ibrnav eval-track`: the JSON summary and per-trial errors, and a recording with the
    particles, estimate, truth and observed vs rendered images."""
    out, rrd = tmp_path / "track.json", tmp_path / "track.rrd"
    args = _parse(["eval-track", "synthetic:office", "--trials", "1", "--steps", "3", "--kidnap-step", "-1",
                   "--particles", "200", "--max-particles", "300", "--known-start",
                   "--json", str(out), "--save", str(rrd)])
    assert args.func(args) == 0
    res = json.loads(out.read_text())
    assert len(res["trials"]) == 1 and "recovered_rate" not in res  # no kidnapping
    trial = res["trials"][0]
    assert len(trial["error_m"]) == 3 and max(trial["error_m"]) < 0.25  # tracked from the known start
    assert res["converged_rate"] == 1.0 and trial["steps_to_converge"] == 0
    paths = set(RrdReader(rrd).stream().collect().schema().entity_paths())
    assert {"/world/particles", "/world/estimate", "/world/robot", "/localization/observed",
            "/localization/rendered_at_estimate", "/plots/estimate_error_m"} <= paths


def test_eval_track_cli_rejects_a_non_synthetic_scene():
    args = _parse(["eval-track", "/no/such/scene", "--trials", "1"])
    with pytest.raises(InputError, match="synthetic"):
        args.func(args)
