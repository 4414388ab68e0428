"""`ibrnav eval-track` end to end: the JSON summary, the rerun entities, a bad scene named."""

import json

import pytest
from rerun.chunk import RrdReader

from ibr.errors import InputError


def test_eval_track_writes_json_and_the_rerun_entities(ibrnav_command, tmp_path, gl_ctx):
    """`ibrnav eval-track`: the JSON summary and per-trial errors, and a recording with the
    particles, estimate, truth and observed vs rendered images."""
    out, rrd = tmp_path / "track.json", tmp_path / "track.rrd"
    assert ibrnav_command("eval-track", "synthetic:office", "--trials", "1", "--steps", "5", "--kidnap-step", "-1",
                          "--particles", "300", "--known-start",
                          "--json", out, "--save", rrd) == 0
    res = json.loads(out.read_text())
    assert len(res["trials"]) == 1 and "recovered_rate" not in res  # no kidnapping
    trial = res["trials"][0]
    assert len(trial["error_m"]) == 5 and max(trial["error_m"]) < 0.25  # tracked from the known start
    # the filter claims convergence once it has been one tight mode with no rival for two photos
    assert res["converged_rate"] == 1.0 and trial["steps_to_converge"] == 1
    assert res["settings"]["n_global"] == 300 and res["converged_wrong_trials"] == 0
    paths = set(RrdReader(rrd).stream().collect().schema().entity_paths())
    assert {"/world/particles", "/world/estimate", "/world/robot", "/localization/observed",
            "/localization/rendered_at_estimate", "/plots/estimate_error_m"} <= paths


def test_eval_track_rejects_a_non_synthetic_scene(ibrnav_command):
    with pytest.raises(InputError, match="synthetic"):
        ibrnav_command("eval-track", "/no/such/scene", "--trials", "1")
