"""The verdict (`localization.confidence.judge`) on known alignments: agreement with the
model's own photos, trusted support, and rivals that would be answers themselves."""

import numpy as np

from localization.confidence import ConfidenceConfig, judge, plausible
from localization.direct_alignment import Alignment
from localization.render_localizer import answer


def alignment(cost, explained, trusted=0.05):
    return Alignment(np.eye(4), cost, explained, trusted)


def test_a_pose_that_explains_what_the_map_photos_do_is_localised():
    v = judge(alignment(0.95, 0.96), reference=0.97, rival_gap=None)
    assert v.localized and v.confidence > 0.9


def test_a_pose_that_explains_little_is_not_localised():
    v = judge(alignment(0.99, 0.3), reference=0.97, rival_gap=None)
    assert not v.localized and "explains 0.30" in v.reason


def test_a_plausible_rival_at_the_same_cost_makes_it_ambiguous():
    assert plausible(alignment(0.951, 0.95), reference=0.97)
    v = judge(alignment(0.95, 0.96), reference=0.97, rival_gap=0.001)
    assert not v.localized and "distinct pose" in v.reason


def test_a_pose_that_explains_far_less_is_no_rival():
    assert not plausible(alignment(0.9501, 0.19), reference=0.97)


def posed(x, cost, explained, trusted=0.05):
    """An alignment at camera centre (x, 0, 0), world metres."""
    T = np.eye(4)
    T[0, 3] = -x
    return Alignment(T, cost, explained, trusted)


def test_the_answer_is_the_cheapest_plausible_pose_not_the_cheapest():
    """Courtyard seed 8, query 8: the wrong pose sees more trusted model and costs less, but
    explains 0.29 of the photo; the right one explains 0.90."""
    wrong, right = posed(3.5, 0.9448, 0.29, 0.21), posed(0.0, 0.9596, 0.90, 0.17)
    best, gap = answer([wrong, right], 0.97, ConfidenceConfig(), depth_m=5.0, focal_px=300.0)
    assert best is right and gap is None  # the wrong pose is no rival
    rival = posed(1.0, 0.9600, 0.95)  # a distinct plausible pose at nearly the same cost
    best, gap = answer([wrong, rival, right], 0.97, ConfidenceConfig(), depth_m=5.0, focal_px=300.0)
    assert best is right and abs(gap - 0.0004) < 1e-9
    assert not judge(best, 0.97, gap).localized
    best, _ = answer([wrong, posed(1.0, 0.99, 0.2)], 0.97, ConfidenceConfig(), depth_m=5.0, focal_px=300.0)
    assert best is wrong  # no plausible pose: the cheapest, which the verdict then rejects
