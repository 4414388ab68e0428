"""The run loop of the Scenic Route Planner (Mendez et al. Sec. 4.1.1): which stereo pairs a
frame reconstructs, for the collaborative and the SfM decision."""

import numpy as np

from explore.scenic.collab import COLLABORATIVE, SFM
from explore.scenic.pose import CameraModel
from explore.scenic.session import ScenicSession, SessionConfig
from explore.scenic.smc import SMCConfig

CONFIG = SessionConfig(agents=2, gt_samples=2000, camera=CameraModel(160, 120, 60.0),
                       smc=SMCConfig(n_particles=40))


def forced(session, mode: str, moves: np.ndarray):
    """Replace the planner by a fixed decision: poses + moves (A, 4)."""
    session.plan = lambda goals: (mode, 0 if mode == COLLABORATIVE else -1,
                                  session.poses + moves, {})
    return session


def pairs_done(session, calls: list):
    original = session._reconstruct

    def spy(qa, img_a, qb, img_b):
        calls.append((qa.copy(), qb.copy()))
        original(qa, img_a, qb, img_b)
    session._reconstruct = spy


def test_collaborative_frame_pairs_mover_with_partner_and_with_itself(office):
    s = ScenicSession(office, CONFIG, np.random.default_rng(0))
    before = s.poses.copy()
    move = np.array([[0.0, 0.3, 0.0, 0.1], [0.0, 0.0, 0.0, 0.0]])  # agent 0 moves, 1 holds still
    calls = []
    pairs_done(forced(s, COLLABORATIVE, move), calls)
    report = s.step()
    assert report.mode == COLLABORATIVE
    np.testing.assert_allclose(s.poses[1], before[1])
    np.testing.assert_allclose(calls[0][0], before[1])            # partner (still) ...
    np.testing.assert_allclose(calls[0][1], before[0] + move[0])  # ... with the mover's new view
    np.testing.assert_allclose(calls[1][0], before[0])            # mover's SfM pair
    np.testing.assert_allclose(calls[1][1], before[0] + move[0])
    assert len(calls) == 3  # the still agent's zero-baseline "pair" is skipped inside


def test_sfm_frame_pairs_each_camera_with_its_last_view(office):
    s = ScenicSession(office, CONFIG, np.random.default_rng(1))
    before, n0 = s.poses.copy(), s.n_pairs
    move = np.array([[0.0, 0.3, 0.0, 0.1], [0.0, -0.3, 0.0, -0.1]])
    calls = []
    pairs_done(forced(s, SFM, move), calls)
    s.step()
    assert len(calls) == 2 and s.n_pairs == n0 + 2
    for a in range(2):
        np.testing.assert_allclose(calls[a][0], before[a])
        np.testing.assert_allclose(calls[a][1], before[a] + move[a])
