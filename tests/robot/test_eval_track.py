"""Tracking evaluation in a synthetic world: the convergence rule, and a kidnapped robot
recovered by the render-likelihood particle filter."""

import numpy as np

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
