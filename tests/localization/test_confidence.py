"""The verdict (`localization.confidence.judge`) on known alignments: agreement with the
model's own photos, trusted support, and rivals that would be answers themselves."""

import numpy as np

from localization.confidence import judge, plausible
from localization.direct_alignment import Alignment


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
