import numpy as np
import pytest

from ibr.camera import intrinsics_from_fov
from localization.pose_views import se2_views
from localization.render_likelihood import (BatchedLikelihood, LikelihoodConfig, likelihood_renderer, luminance,
                                            pixel_weights, reference_tile_scores, scores_to_loglik)
from robot.protocol import forward_camera_mount, robot_camera

TRUE = np.array([-1.5, -2.5, 0.3])


@pytest.fixture(scope="module")
def setup(office):
    K = intrinsics_from_fov(60, 320, 240)
    mount = forward_camera_mount(0.4)
    observed = office.photograph(robot_camera(TRUE, K, (320, 240), mount))
    rng = np.random.default_rng(0)
    poses = np.c_[rng.uniform(-2.5, 2.5, 60), rng.uniform(-3.5, 3.5, 60), rng.uniform(-3, 3, 60)]
    poses[0] = TRUE
    cams = [robot_camera(p, K, (320, 240), mount).scaled(0.2) for p in poses]
    return office, observed, poses, cams, mount


def test_batched_scores_equal_per_particle_reference(setup, gl_ctx):
    office, observed, poses, cams, _ = setup
    lik = BatchedLikelihood(office.renderer(gl_ctx), light=office.light)
    lik.set_observation(observed, (64, 48))
    batched = lik.tile_scores(cams)
    ref = reference_tile_scores(office.renderer(gl_ctx), cams, luminance(observed, (64, 48)), office.light)
    np.testing.assert_allclose(batched, ref, atol=2e-3)


def test_array_path_equals_camera_path(setup, gl_ctx):
    office, observed, poses, cams, mount = setup
    lik = BatchedLikelihood(office.renderer(gl_ctx), light=office.light)
    lik.set_observation(observed, (64, 48))
    clip, eyes = se2_views(poses, cams[0], mount)
    np.testing.assert_allclose(lik.view_scores(clip, eyes), lik.tile_scores(cams), atol=1e-6)


@pytest.mark.parametrize("score", ["ncc", "ssd", "robust"])
def test_likelihood_peaks_at_the_true_pose(setup, gl_ctx, score):
    office, observed, poses, cams, _ = setup
    config = LikelihoodConfig(score=score, temperature=0.1 if score == "ssd" else 0.05)
    lik = BatchedLikelihood(office.renderer(gl_ctx), config, light=office.light)
    lik.set_observation(observed)
    loglik = scores_to_loglik(lik.tile_scores(cams), config)
    assert np.argmax(loglik) == 0
    # and it falls off with distance from the truth
    near = [robot_camera(TRUE + d, cams[0].K, (64, 48), setup[4]) for d in
            ([0.05, 0, 0], [0.3, 0, 0], [1.0, 0, 0])]
    ll = scores_to_loglik(lik.tile_scores(near), config)
    assert ll[0] > ll[1] > ll[2]


def test_ncc_and_robust_cost_ignore_exposure(setup, gl_ctx):
    """NCC and the robust cost (exposure fitted, residuals truncated at the photo's own
    contrast) barely change when the photo is 40 % darker."""
    office, observed, poses, cams, _ = setup
    lik = BatchedLikelihood(office.renderer(gl_ctx), light=office.light)
    lik.set_observation(observed)
    a = lik.tile_scores(cams[:5])
    lik.set_observation((observed * 0.6).astype(np.uint8))
    b = lik.tile_scores(cams[:5])
    np.testing.assert_allclose(a[:, [0, 3]], b[:, [0, 3]], atol=0.03)


def test_lean_renderer_batched_equals_reference_and_tracks_full_renderer(setup, gl_ctx):
    """The likelihood's lean renderer (trilinear, no anisotropic filtering): the batched
    pass equals its per-particle reference, and its NCC stays close to the photo renderer's."""
    office, observed, poses, cams, _ = setup
    lean = likelihood_renderer(office.mesh, gl_ctx, office.background)
    assert lean.anisotropy == 1.0 and office.renderer(gl_ctx).anisotropy > 1.0
    lik = BatchedLikelihood(lean, light=office.light)
    lik.set_observation(observed, (64, 48))
    batched = lik.tile_scores(cams)
    ref = reference_tile_scores(lean, cams, luminance(observed, (64, 48)), office.light)
    np.testing.assert_allclose(batched, ref, atol=2e-3)
    full = BatchedLikelihood(office.renderer(gl_ctx), light=office.light)
    full.set_observation(observed, (64, 48))
    np.testing.assert_allclose(batched[:, 0], full.tile_scores(cams)[:, 0], atol=0.1)
    assert np.argmax(batched[:, 0] * batched[:, 2]) == 0  # still peaks at the truth


def test_render_mcl_is_coarse_and_tempered_while_spread(setup, gl_ctx):
    """RenderMCL compares at the coarse size while the particles are spread and at the full
    size once they gather; its weights are the likelihood at temperature T (1 + k spread)."""
    import shapely

    from ibr.camera import Camera
    from localization.particle_filter import ParticleFilter, ParticleFilterConfig
    from localization.render_mcl import RenderMCL, RenderMCLConfig

    office, observed, poses, cams, mount = setup
    free = shapely.box(-2.8, -3.8, 2.8, 3.8)
    lik = BatchedLikelihood(likelihood_renderer(office.mesh, gl_ctx, office.background), light=office.light)
    camera = Camera(intrinsics_from_fov(60, 320, 240), 320, 240)
    for spread, size in ((None, (32, 24)), (0.05, (64, 48))):
        pf = ParticleFilter(free, ParticleFilterConfig(n_particles=200), np.random.default_rng(0))
        pf.init_uniform() if spread is None else pf.init_gaussian(TRUE, [spread, spread, 0.02])
        mcl = RenderMCL(pf, lik, camera, mount, RenderMCLConfig())
        s = mcl.spread_m()
        particles = pf.particles.copy()
        assert mcl.measure(observed) == size
        clip, eyes = se2_views(particles, camera.scaled(size[0] / 320), mount)
        lik.set_observation(observed, size)
        T = lik.config.temperature * (1 + mcl.config.temper_per_m * s)
        expected = scores_to_loglik(lik.view_scores(clip, eyes), lik.config, T)
        np.testing.assert_allclose(pf.log_w - pf.log_w.max(), expected - expected.max(), atol=1e-3)


def test_pixel_weights_fall_to_zero_at_occlusion_boundaries_over_the_band():
    """A near square (2 m) on a far wall (5 m), seen 96 px wide: boundary pixels weigh 0
    at any band; with a band of 1/12 of the width (8 px) the weight is distance / 8 px
    from the boundary, 1 beyond; a band under a pixel is the shader's one-pixel rule."""
    depth = np.full((72, 96), 5.0, np.float32)
    depth[20:52, 30:66] = 2.0
    trust = np.ones_like(depth)
    one_px = pixel_weights(depth, trust, 0.1)
    assert one_px[20, 40] == 0 and one_px[19, 40] == 0 and one_px[21, 40] == 1 and one_px[36, 48] == 1
    np.testing.assert_array_equal(pixel_weights(depth, trust, 0.1, band=0.5 / 96), one_px)
    banded = pixel_weights(depth, trust, 0.1, band=1 / 12)
    assert banded[20, 40] == 0 and banded[19, 40] == 0
    np.testing.assert_allclose([banded[24, 45], banded[15, 45]], 0.5)  # 4 px from a boundary pixel
    assert banded[36, 48] == 1 and banded[5, 5] == 1  # the image border is no boundary
    assert (banded <= one_px).all()
