"""Foster et al.'s rendering-quality heuristic: the batched GPU pass against the numpy
per-pixel reference, and known answers (a candidate at a source's pose, an unseen wall)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
import trimesh

from explore.view_quality import ViewQuality, ViewQualityConfig, ViewQualityError, resampled
from ibr.camera import Camera, intrinsics_from_fov
from ibr.errors import InputError

SIZE = (64, 48)


def forward_mount(height_m: float) -> np.ndarray:
    """cam_from_robot of a level camera looking along the robot's x axis."""
    R = np.array([[0, -1.0, 0], [0, 0, -1.0], [1.0, 0, 0]])  # rows: camera axes in robot frame
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ np.array([0, 0, height_m])
    return T


@pytest.fixture(scope="module")
def proxy(office):
    return trimesh.Trimesh(office.mesh.vertices, office.mesh.faces, process=False)


@pytest.fixture(scope="module")
def vq(office, proxy, gl_ctx):
    return ViewQuality(proxy, office.default_cameras(24, 160, 120), gl_ctx, ViewQualityConfig(size=SIZE))


def _poses(office, n, seed):
    rng = np.random.default_rng(seed)
    region = office.free_space.buffer(-0.3)
    xy = rng.uniform([-3, -4], [3, 4], (20 * n, 2))
    xy = xy[shapely.contains_xy(region, xy[:, 0], xy[:, 1])][:n]
    return np.c_[xy, rng.uniform(-np.pi, np.pi, n)]


def test_gpu_matches_numpy_reference(office, vq):
    template = Camera(intrinsics_from_fov(70, *SIZE), *SIZE)
    clip, eyes = vq.pose_views(_poses(office, 12, 0), template, forward_mount(1.1))
    gpu = vq.view_stats(clip, eyes)
    ref = vq.score_views_numpy(clip, eyes)
    assert gpu.shape == (12, 3)
    assert np.all(gpu[:, 1] > 0.5)  # the views look at the room
    np.testing.assert_allclose(gpu[:, 0], ref[:, 0], atol=2e-3)
    np.testing.assert_allclose(gpu[:, 1:], ref[:, 1:], atol=3e-3)
    assert np.ptp(gpu[:, 0]) > 0.05  # the scores discriminate between views


def test_score_poses_equals_score_cameras(office, vq):
    template = Camera(intrinsics_from_fov(70, 320, 240), 320, 240)
    poses = _poses(office, 5, 1)
    mount = forward_mount(1.1)
    from localization.pose_views import se2_robot_from_world
    small = resampled(template, *SIZE)
    cams = [small.with_pose(mount @ T) for T in se2_robot_from_world(poses)]
    np.testing.assert_allclose(vq.score_poses(poses, template, mount), vq.score_cameras(cams), atol=1e-5)


def test_candidate_at_a_source_scores_zero(office, vq):
    sources = office.default_cameras(24, 160, 120)
    cams = [resampled(sources[k], *SIZE) for k in (0, 7, 15)]
    stats = vq.view_stats(np.stack([c.gl_clip_from_world(0.05, 1000.0) for c in cams]),
                          np.stack([c.center for c in cams]))
    assert np.all(stats[:, 2] > 0.97)  # the source sees (nearly) every pixel it shares
    assert np.all(stats[:, 0] < 0.01)  # ... from exactly the desired direction (radians)


def test_unseen_wall_scores_worse_than_covered(proxy, gl_ctx):
    K = intrinsics_from_fov(60, 160, 120)
    # sources all look at the +y wall from around y = -1
    sources = [Camera.look_at((x, -1.0, 1.2), (x, 4.0, 1.2), K, 160, 120) for x in np.linspace(-2, 2, 6)]
    vq = ViewQuality(proxy, sources, gl_ctx, ViewQualityConfig(size=SIZE))
    Kc = intrinsics_from_fov(60, *SIZE)
    covered = Camera.look_at((0.3, 0.5, 1.2), (0.3, 4.0, 1.3), Kc, *SIZE)
    unseen = Camera.look_at((0.3, -1.5, 1.2), (0.3, -4.0, 1.3), Kc, *SIZE)
    s_cov, s_un = vq.score_cameras([covered, unseen])
    stats = vq.view_stats(np.stack([c.gl_clip_from_world(0.05, 1000.0) for c in (covered, unseen)]),
                          np.stack([c.center for c in (covered, unseen)]))
    assert stats[0, 2] > 0.9 and stats[1, 2] < 0.1
    assert s_cov < 0.5
    assert s_un > 2.5  # unseen pixels score pi
    assert s_un > s_cov + 2.0


def test_bad_input_is_named(proxy, vq, gl_ctx):
    with pytest.raises(InputError, match="source"):
        ViewQuality(proxy, [], gl_ctx)
    with pytest.raises(ViewQualityError, match="clip"):
        vq.score_views(np.eye(4), np.zeros(3))
    with pytest.raises(ViewQualityError, match="NaN"):
        vq.score_views(np.full((1, 4, 4), np.nan), np.zeros((1, 3)))
    with pytest.raises(ViewQualityError, match="config.size"):
        vq.score_cameras([Camera(intrinsics_from_fov(60, 100, 80), 100, 80)])


def test_storage_buffer_path_agrees_with_shared_memory_path(office, proxy, vq, gl_ctx, monkeypatch):
    import explore.view_quality as view_quality

    monkeypatch.setattr(view_quality, "MAX_SHARED_SOURCES", 8)  # 24 sources: no shared copy
    vq_ssbo = ViewQuality(proxy, office.default_cameras(24, 160, 120), gl_ctx, ViewQualityConfig(size=SIZE))
    template = Camera(intrinsics_from_fov(70, *SIZE), *SIZE)
    poses = _poses(office, 6, 2)
    np.testing.assert_allclose(vq_ssbo.score_poses(poses, template, forward_mount(1.1)),
                               vq.score_poses(poses, template, forward_mount(1.1)), atol=1e-6)


def test_release_frees_gl_objects(proxy, gl_ctx):
    K = intrinsics_from_fov(60, 80, 60)
    vq = ViewQuality(proxy, [Camera.look_at((0, 0, 1.2), (0, 3, 1.2), K, 80, 60)], gl_ctx,
                     ViewQualityConfig(size=SIZE))
    cam = Camera.look_at((0, 0.2, 1.2), (0, 3, 1.2), intrinsics_from_fov(60, *SIZE), *SIZE)
    vq_score = vq.score_cameras([cam])[0]
    assert vq_score < 0.2
    vq.release()
    again = ViewQuality(proxy, [Camera.look_at((0, 0, 1.2), (0, 3, 1.2), K, 80, 60)], gl_ctx,
                        ViewQualityConfig(size=SIZE))  # the context still works
    assert again.score_cameras([cam])[0] == pytest.approx(vq_score, abs=1e-6)
    assert gl_ctx.error == "GL_NO_ERROR"


def test_background_score_counts_missing_proxy(office, gl_ctx):
    floor_faces = np.all(office.mesh.vertices[office.mesh.faces][:, :, 2] == 0.0, axis=1)
    floor = trimesh.Trimesh(office.mesh.vertices, office.mesh.faces[floor_faces], process=False)
    K = intrinsics_from_fov(60, 80, 60)
    sources = [Camera.look_at((x, -1.0, 1.2), (x, 1.0, 0.0), K, 80, 60) for x in (-1.0, 0.0, 1.0)]
    cam = Camera.look_at((0.0, -1.5, 1.2), (0.0, 3.0, 1.0), intrinsics_from_fov(60, *SIZE), *SIZE)
    views = (cam.gl_clip_from_world(0.05, 1000.0)[None], cam.center[None])
    plain = ViewQuality(floor, sources, gl_ctx, ViewQualityConfig(size=SIZE)).view_stats(*views)[0]
    holes = ViewQuality(floor, sources, gl_ctx, ViewQualityConfig(size=SIZE, background_score=np.pi))
    score, frac = holes.score_views(*views)[0], plain[1]
    assert 0.2 < frac < 0.8  # the floor fills part of the view, the rest is a "hole"
    assert score == pytest.approx(frac * plain[0] + (1 - frac) * np.pi, abs=1e-6)


def test_seen_free_is_the_space_the_photos_saw_through(office, vq):
    """Known answers in the office (sources at 1.2 m looking out from the centre): the space
    just ahead of each source was seen through; points behind the walls, inside the cabinet
    or the shelf (taller than 1.2 m) were not, whatever a free-space slice would say."""
    sources = office.default_cameras(24, 160, 120)
    ahead = np.array([c.center + 0.6 * c.world_from_cam[:3, 2] for c in sources])
    assert vq.seen_free(ahead, margin_m=0.2).mean() > 0.9
    outside = np.array([[3.4, 0.0], [-3.4, 1.0], [0.5, 4.4], [0.0, -4.5], [5.0, 5.0]])
    solid = np.array([[2.75, -0.2], [2.7, 0.3], [0.0, 3.85], [-0.6, 3.8]])  # cabinet, shelf
    for pts in (outside, solid):
        assert not vq.seen_free(np.c_[pts, np.full(len(pts), 1.2)], margin_m=0.2).any()
    assert vq.seen_free(np.zeros((0, 3))).shape == (0,)


def test_sight_lines_another_sensor_found_blocked_do_not_count(office, vq):
    """The space ahead of the sources stops counting as seen through when every sight line
    to it is blocked (the ultrasonic met a surface the proxy lacks), and only where it is."""
    sources = office.default_cameras(24, 160, 120)
    ahead = np.array([c.center + 0.6 * c.world_from_cam[:3, 2] for c in sources])
    seen = vq.seen_free(ahead, margin_m=0.2)
    assert not vq.seen_free(ahead, 0.2, blocked=lambda c, p: np.ones(len(p), bool)).any()
    east = lambda c, p: p[:, 0] > 0.0  # noqa: E731 - sight lines to points east of x = 0 blocked
    kept = vq.seen_free(ahead, 0.2, blocked=east)
    assert not kept[ahead[:, 0] > 0].any()
    np.testing.assert_array_equal(kept[ahead[:, 0] <= 0], seen[ahead[:, 0] <= 0])
