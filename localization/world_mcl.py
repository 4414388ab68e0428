"""SE(2) Monte Carlo localisation with rendered views whose settings come from the world:
the free-space area, the camera's field of view and the measured shape of the likelihood.
The same code localises in a 6 x 8 m office, a small apartment and a 40 x 40 m courtyard.

Settings (`MCLSettings.for_world`), nav2_amcl's per-map parameters derived instead of set:
- the likelihood's basin: the half-width of its peak in position (m) and heading (rad),
  measured on the map itself (`measure_basin`: the map's own views as observations, the
  likelihood on rings around them; no photos, no truth);
- the global particle count: `per_basin` particles per basin cell of the free space
  (area / (pi basin_m^2) cells x pi / basin_rad headings), bounded by `n_cap` (a compute
  budget, not a size of any world);
- KLD-sampling bins: half a basin (Fox 2003: the bin is the resolution at which the
  posterior must be represented, here the resolution the likelihood resolves);
- roughening: a twentieth of a basin.

The step (`WorldMCL.step`): odometry prediction (Thrun's model), the horizon-free NCC of
`level_view_likelihood`, tempered so that the effective sample size stays at least
`ess_min` of the particles (adaptive tempering, as in annealed / SMC samplers: a spread set
is not collapsed onto a few lucky particles, and two places the likelihood cannot tell
apart both keep particles until the motion separates them), augmented MCL (w_slow / w_fast
on the untempered likelihood, nav2_amcl's recovery_alpha_slow / fast) and, when the
short-term likelihood collapses, a global injection that keeps the current cloud beside
`n_global` new particles (sensor resetting, Lenser & Veloso 2000, without throwing
away a hypothesis that may still be right).

Global localisation, the reset's new particles and augmented MCL's injected ones come from
the photo, not from a uniform prior, when a `PanoramaIndex` is given: the `n_global`
(position, heading) cells of a grid over the free space that fit the photo best, half of
them ranked by the photo alone and half by the track of the last photos along the odometry
(`localization.view_search`; the measurement's own samples, mixture / dual MCL, Thrun et
al. 2001). A uniform prior of any affordable size
misses the likelihood's basin in a large free space (the courtyard: ~60,000 basin cells);
the photo's best cells hold the truth's. The filter claims convergence only when the
cloud is unimodal and tight: `converged_mass` of the weight within the success tolerance
of the estimate, no rival place fits the photos as well, for `confirm_steps` steps in a row,
each with the photo fitting at least as well as the filter's long-run average (w_fast >=
w_slow: a filter that is injecting particles does not claim).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from localization.level_view_likelihood import LevelViewLikelihood
from localization.motion_models import sample_motion_model_odometry, se2_backward, wrap_angle
from localization.particle_filter import (ParticleFilter, ParticleFilterConfig, effective_sample_size,
                                          sample_free_poses)
from localization.view_search import PanoramaIndex


@dataclass(frozen=True)
class Basin:
    """The likelihood's peak: median half-widths in position (m) and heading (rad) over the
    sampled poses. (Medians: a mean of 1 / cell size would be dominated by the few poses
    that face a wall at arm's length, whose peaks are a few cm wide.)"""

    m: float
    rad: float

    @property
    def cells_per_m2(self) -> float:
        """Basin cells per m^2 of free space: a cell is a disc of radius `m` times a heading
        sector of 2 `rad`."""
        return 1.0 / (np.pi * self.m**2) * (np.pi / self.rad)


def measure_basin(lik: LevelViewLikelihood, free, rng: np.random.Generator, n_poses: int = 32,
                  size: tuple[int, int] = (32, 24)) -> Basin:
    """The likelihood's peak half-widths, medians over `n_poses` free poses: each pose's
    rendered view is the observation; the NCC is evaluated on 8 directions at geometric
    distances (from 1/400 to 1/4 of the free space's extent: scale-free) and on geometric
    heading offsets; the half-width is where the mean NCC first falls half way from the
    peak to the median NCC of random poses."""
    extent = float(np.sqrt(free.area))
    dists = np.geomspace(extent / 400, extent / 4, 20)
    angles = np.geomspace(np.radians(0.5), np.pi, 20)
    dirs = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    poses = sample_free_poses(free, n_poses, rng)
    far = sample_free_poses(free, 64, rng)
    hw_m, hw_rad = [], []
    # NCC is invariant to the observation's scale: the map's own view stands in for a photo
    for p in poses:
        obs = lik.render(p[None], size)[0]
        lik._observed = obs
        base = float(np.median(lik.ncc(far, size)))
        ring = np.array([[p[0] + d * np.cos(a), p[1] + d * np.sin(a), p[2]] for d in dists for a in dirs])
        turn = np.array([[p[0], p[1], p[2] + s * t] for t in angles for s in (-1, 1)])
        v_ring = lik.ncc(ring, size).reshape(len(dists), len(dirs)).mean(axis=1)
        v_turn = lik.ncc(turn, size).reshape(len(angles), 2).mean(axis=1)
        hw_m.append(_half_width(dists, v_ring, 1.0, base))
        hw_rad.append(_half_width(angles, v_turn, 1.0, base))
    lik._observed = None
    return Basin(float(np.median(hw_m)), float(np.median(hw_rad)))


def _half_width(x: np.ndarray, v: np.ndarray, peak: float, base: float) -> float:
    """Where v first falls below half way from `peak` to `base`, interpolated in log x
    between the grid points (x[0] if at once, the last x if never)."""
    half = (peak + base) / 2
    below = np.flatnonzero(v < half)
    if not len(below):
        return float(x[-1])
    i = below[0]
    if i == 0:
        return float(x[0])
    f = (v[i - 1] - half) / max(v[i - 1] - v[i], 1e-9)
    return float(np.exp(np.log(x[i - 1]) + f * (np.log(x[i]) - np.log(x[i - 1]))))


@dataclass(frozen=True)
class MCLSettings:
    """What `for_world` derives; all sizes in metres and radians."""

    basin: Basin
    n_global: int
    """Particles of a global (re-)initialisation (with a search: the photo's `n_global`
    best cells, one particle each), and KLD-sampling's ceiling."""
    kld_bin: tuple[float, float, float]
    roughening: tuple[float, float, float]

    @classmethod
    def for_world(cls, free_area_m2: float, basin: Basin, per_basin: float = 0.5,
                  n_min: int = 1000, n_cap: int = 6000) -> MCLSettings:
        """per_basin: particles per basin cell (position x heading) of the free space;
        n_min, n_cap: bounds of the count (a floor for tiny maps; the compute budget of one
        step, ~1.5 s at 32x24 on a software renderer)."""
        n = int(np.clip(np.ceil(per_basin * free_area_m2 * basin.cells_per_m2), n_min, n_cap))
        half = (basin.m / 2, basin.m / 2, basin.rad / 2)
        rough = (basin.m / 20, basin.m / 20, basin.rad / 20)
        return cls(basin, n, half, rough)

    def filter_config(self, **overrides) -> ParticleFilterConfig:
        """The particle filter's config: counts, bins and roughening from these settings;
        the global re-initialisation is `WorldMCL`'s (keeps the cloud), so off here."""
        return replace(ParticleFilterConfig(n_particles=self.n_global, n_max=self.n_global,
                                            kld_bin=self.kld_bin, roughening=self.roughening,
                                            reinit_ratio=0.0), **overrides)


@dataclass(frozen=True)
class WorldMCLConfig:
    coarse_size: tuple[int, int] = (32, 24)
    """Comparison size (px) until the filter has converged."""
    fine_size: tuple[int, int] = (64, 48)
    """Comparison size (px) once it has."""
    temperature: float = 0.05
    """Temperature of the NCC log-likelihood for the augmented-MCL averages (comparable
    from step to step), and the ceiling of the step's calibrated least temperature
    (`calibrated_temperature`) (NCC units, the same in every world)."""
    ess_min: float = 0.1
    """Temper so that the effective sample size stays at least this fraction of N."""
    reinit_ratio: float = 0.1
    """Inject `n_global` uniform particles when w_fast / w_slow falls below this."""
    converged_m: float = 0.3
    """Success tolerance in position (m): set by the caller from what success means (the
    eval uses the robot's diameter); not a size of the world."""
    converged_rad: float = np.radians(10.0)
    """Success tolerance in heading (rad)."""
    converged_mass: float = 0.9
    """Claim convergence when this fraction of the weight is within the tolerance of the
    estimate (one tight mode) ..."""
    probe_size: tuple[int, int] = (16, 12)
    """Comparison size (px) of the uniform probes: cheap, and the widest basin."""
    probe_fraction: float = 0.25
    """... and none of `probe_fraction` x n_global uniform poses, scored at the coarse size
    at every step, matches the photo as well as the estimate does away from it (those that
    do join the cloud as other modes: a tight cloud is not evidence that no other place
    fits; mixture MCL's samples from the measurement, Thrun et al. 2001) ..."""
    confirm_steps: int = 2
    """... at this many consecutive steps, each with the photo fitting at least as well as
    the filter's long-run average (`WorldMCL._unsurprised`)."""
    rival_nats: float = 3.0
    """A far pose is a rival while its log-likelihood, summed over the photos since it was
    found, is within this of the estimate's (at the least temperature: a likelihood ratio
    of at least e^-3 = 5 %)."""
    max_rivals: int = 64
    """Most rival poses remembered from step to step (the best-fitting)."""
    history_steps: int = 5
    """A newly found rival is scored on up to this many earlier photos as well (moved back
    along the odometry), so that its test starts with the evidence of the drive so far: a
    rival must fit the last few photos, not this one only (measured in the courtyard: each
    step's probes found poses that fit that one photo as well as the truth, and a claim was
    never made). A count of photos, the same in every world."""
    track_steps: int = 5
    """Photos of the track whose cells the search also ranks (`_searched`): as many as a
    rival's history, for the same reason (at most `history_steps` + 1: the history holds
    the earlier ones)."""


@dataclass
class WorldStep:
    estimate: np.ndarray
    """(3,) mean of the heaviest mode."""
    converged: bool
    """Whether the filter claims one tight mode."""
    mass: float
    """Weight within the tolerance of the estimate."""
    n_particles: int
    temperature: float
    size: tuple[int, int]
    injected: int
    reset: bool
    """Whether the likelihood collapsed and `n_global` uniform particles were added."""


def ess_temperature(log_w: np.ndarray, loglik: np.ndarray, ess_min: float) -> float:
    """The least factor t >= 1 such that weighting `log_w` by `loglik / t` keeps the effective
    sample size at least `ess_min` of N (bisection on log t)."""
    target = ess_min * len(log_w)
    if effective_sample_size(log_w + loglik) >= target:
        return 1.0
    lo, hi = 0.0, np.log(1e6)
    for _ in range(30):
        mid = (lo + hi) / 2
        if effective_sample_size(log_w + loglik / np.exp(mid)) >= target:
            hi = mid
        else:
            lo = mid
    return float(np.exp(hi))


def calibrated_temperature(ncc: np.ndarray, contrast: float, ceiling: float) -> float:
    """The least temperature of the NCC log-likelihood -(1 - NCC) / T at this step (NCC
    units): how far the best view of the cloud falls short of the photo, 1 - max NCC. That
    shortfall is the model's mismatch with the photo at (or near) the true pose (lighting,
    texture filtering, resolution); poses that fall short of the best by that much again
    are e times less likely. A fixed 0.05 is right where the view at the truth scores ~0.95
    (the office) but flattens the likelihood 5 to 10 times where it scores 0.99 (the
    courtyard, two times oversampled), and the weight then gathered on the truth over ~25
    photos instead of a few. Bounded below by what 8-bit quantisation alone costs the NCC
    (the quantisation noise's variance, 1 / (12 255^2), over the photo's `contrast`, its
    horizon-free variance), above by `ceiling` (the configured temperature: a lost cloud,
    whose best view fits badly, is not made flatter than before)."""
    floor = 1.0 / (12 * 255.0**2) / max(contrast, 1e-12)
    return float(np.clip(1.0 - np.max(ncc), floor, ceiling)) if len(ncc) else ceiling


def local_ring(pose: np.ndarray, step_m: float, step_rad: float) -> np.ndarray:
    """(20, 3) poses around `pose`: 8 directions at one and two `step_m` (same heading), and
    the heading turned by one and two `step_rad` either way."""
    a = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    out = [[pose[0] + r * np.cos(b), pose[1] + r * np.sin(b), pose[2]] for r in (step_m, 2 * step_m) for b in a]
    out += [[pose[0], pose[1], pose[2] + k * step_rad] for k in (-2, -1, 1, 2)]
    out = np.array(out)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def mode_estimate(particles: np.ndarray, w: np.ndarray, bin_size) -> np.ndarray:
    """(3,) weighted mean of the particles in the heaviest KLD bin's neighbourhood (the bin
    and its neighbours): the estimate of the heaviest mode, not a mean between modes."""
    keys = np.floor(particles / np.asarray(bin_size)).astype(np.int64)
    uniq, inv = np.unique(keys, axis=0, return_inverse=True)
    mass = np.bincount(inv.ravel(), weights=w, minlength=len(uniq))
    best = uniq[np.argmax(mass)]
    d = np.abs(keys - best)
    d[:, 2] = np.minimum(d[:, 2], np.abs(d[:, 2] - int(np.ceil(2 * np.pi / bin_size[2]))))
    near = (d <= 1).all(axis=1)
    ww = w[near] / w[near].sum()
    p = particles[near]
    return np.array([ww @ p[:, 0], ww @ p[:, 1], np.arctan2(ww @ np.sin(p[:, 2]), ww @ np.cos(p[:, 2]))])


class WorldMCL:
    """pf: the SE(2) particle filter (made from `settings.filter_config()`); lik: the
    level-view likelihood; settings: the world's settings; search: the map's panoramas,
    where global (re-)initialisations draw their particles from (None: uniform)."""

    def __init__(self, pf: ParticleFilter, lik: LevelViewLikelihood, settings: MCLSettings,
                 config: WorldMCLConfig = WorldMCLConfig(), search: PanoramaIndex | None = None):
        self.pf, self.lik, self.settings, self.config = pf, lik, settings, config
        self.search = search
        self._image: np.ndarray | None = None
        if search is not None:  # augmented MCL's injections come from the photo too
            pf.injection_source = lambda n: self._searched(self._image, n, self.settings.n_global)
        self.seed_next = False
        """Whether the next step replaces the cloud by the photo's best poses."""
        self.converged = False
        self.streak = 0
        """Consecutive steps with one tight mode and no rival."""
        self.rivals = np.zeros((0, 3))
        """Poses away from the estimate that the likelihood cannot rule out."""
        self.rival_lr = np.zeros(0)
        """Each rival's summed log-likelihood ratio to the estimate since it was found."""
        self.T = config.temperature
        """This step's least temperature (`calibrated_temperature`)."""
        self.odom = np.zeros(3)
        """The odometry of the current step."""
        self.history: list[tuple[np.ndarray, np.ndarray]] = []
        """(odometry, photo) of the last `history_steps` steps."""

    def step(self, odom_before: np.ndarray, odom_after: np.ndarray, image: np.ndarray) -> WorldStep:
        """Predict with the odometry, weight with the photo, judge, resample."""
        c, pf = self.config, self.pf
        pf.predict(odom_before, odom_after)
        self.odom, self._image = odom_after, image
        if self.seed_next:
            pf._set(self._fresh(image))
            self.seed_next = False
        if len(self.rivals):
            self.rivals = sample_motion_model_odometry(self.rivals, odom_before, odom_after, pf.config.alphas, pf.rng)
        size = c.fine_size if self.converged else c.coarse_size
        self.lik.set_observation(image, size)
        v = self.lik.ncc(pf.particles, size)
        self.T = calibrated_temperature(v, self.lik.observed_contrast(), c.temperature)
        fit = -(1.0 - v) / self.T
        t = ess_temperature(pf.log_w, fit, c.ess_min)
        # the augmented-MCL averages need a likelihood comparable from step to step: at the
        # configured temperature, not the step's calibrated one
        pf.update(fit / t, fit_loglik=-(1.0 - v) / c.temperature)
        w = pf.weights
        est = mode_estimate(pf.particles, w, self.settings.kld_bin)
        mass = self.mass_near(est)
        rivals = self._remembered_rivals(est, t, size)  # the observation is set at `size`
        rivals = self._rivals(image, est, t, size) or rivals
        self.streak = self.streak + 1 if mass >= c.converged_mass and not rivals and self._unsurprised() else 0
        self.converged = self.streak >= c.confirm_steps
        n = len(pf.particles)
        reset = pf.w_slow > 0 and pf.w_fast < c.reinit_ratio * pf.w_slow
        if reset:
            self._global_injection(image)
            injected = self.settings.n_global
        else:
            injected = pf.n_injected if pf.resample_if_needed() else 0
        self.history = (self.history + [(odom_after, image)])[-c.history_steps:]
        return WorldStep(est, self.converged, mass, n, self.T * t, size, injected, reset)

    def _unsurprised(self) -> bool:
        """Whether a step may count towards a claim: once converged always; before, only
        while the photos fit at least as well as the filter's long-run average (augmented
        MCL's w_fast >= w_slow: it injects no particles). A ratio, the same in every world.
        Right after a kidnapping the cloud can settle on a local maximum of the old place
        that no probe beats yet (apartment 1, trial 32: claimed 2.6 m off two steps after
        the kidnapping, while w_fast / w_slow had fallen to 0.57 and particles were being
        injected)."""
        return self.converged or self.pf.injection_probability() == 0.0

    def _rivals(self, image: np.ndarray, est: np.ndarray, t: float, size: tuple[int, int]) -> bool:
        """Whether other poses fit the photo as well as the estimate does:
        - near: a ring at one and two tolerances around it (at this step's comparison
          `size`) fits better than the estimate (it is not the likelihood's local maximum at
          the tolerance's scale: a tight cloud that slid off the peak);
        - far: some of `probe_fraction` x n_global poses (uniform, or with a search the
          photo's best cells) beyond two tolerances have
          a likelihood within `rival_nats` of the estimate's (another place the filter's
          own likelihood cannot rule out). Screened at `probe_size`, the few that pass
          checked at `size`.
        Rivals join the cloud, weighted as the heaviest particle times their likelihood
        ratio to the estimate (at temperature t)."""
        c, pf = self.config, self.pf
        ring = local_ring(est, c.converged_m, c.converged_rad)
        v = self.lik.ncc(np.r_[est[None], ring], size)  # the observation is set at `size`
        near = v[1:] > v[0]
        self._join(ring[near], v[1:][near] - v[0], t)
        margin = c.rival_nats * self.T
        n_probes = max(1, int(c.probe_fraction * self.settings.n_global))
        # with a search, the probes are the photo's best cells: uniform probes miss the
        # basin of another place in a large site as a uniform prior does (measured in
        # courtyard 2: a claim held 21.8 m / 157 deg off for 2 steps, no probe near the truth)
        probes = sample_free_poses(pf.free, n_probes, pf.rng) if self.search is None else \
            self._searched(image, n_probes)
        away = (np.hypot(*(probes[:, :2] - est[:2]).T) > 2 * c.converged_m) | \
               (np.abs(wrap_angle(probes[:, 2] - est[2])) > 2 * c.converged_rad)
        probes = probes[away]
        self.lik.set_observation(image, c.probe_size)
        vp = self.lik.ncc(np.r_[est[None], probes], c.probe_size)
        screened = probes[vp[1:] >= vp[0] - margin]
        far = False
        if len(screened):
            self.lik.set_observation(image, size)
            vs = self.lik.ncc(screened, size)
            rival = np.flatnonzero(vs >= v[0] - margin)
            rival = rival[np.argsort(-vs[rival])[: c.max_rivals]]  # the best-fitting
            # before its past is scored, a new rival climbs towards its place's peak (a
            # probe lands anywhere in a basin, and its offset would count against every photo)
            found, vf = self._climb(screened[rival], size, iters=2)
            dv = vf - v[0]
            lr = self._past_lr(found, est, size) + dv / self.T
            rival = lr >= -c.rival_nats
            self.lik.set_observation(image, size)
            self._join(found[rival], dv[rival], t)
            self.rivals = np.r_[self.rivals, found[rival]]
            self.rival_lr = np.r_[self.rival_lr, lr[rival]]  # the test starts with the past photos
            far = bool(rival.any())
        return bool(near.any()) or far

    def _climb(self, poses: np.ndarray, size: tuple[int, int], iters: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """`poses` (N, 3) each moved `iters` times to the best of itself and its six
        neighbours half a tolerance away, and their NCC (N,) (the observation set at `size`)."""
        c = self.config
        steps = np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]) \
            * np.array([c.converged_m, c.converged_m, c.converged_rad]) / 2
        v = np.zeros(len(poses))
        for _ in range(iters):
            cand = (poses[:, None, :] + steps[None]).reshape(-1, 3)
            vc = self.lik.ncc(cand, size).reshape(len(poses), len(steps))
            best = np.argmax(vc, axis=1)
            poses = cand.reshape(len(poses), len(steps), 3)[np.arange(len(best)), best]
            poses[:, 2] = wrap_angle(poses[:, 2])
            v = vc[np.arange(len(best)), best]
        return poses, v

    def _past_lr(self, poses: np.ndarray, est: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """(N,) summed log-likelihood ratio of `poses` (N, 3) to the estimate over the
        photos of `history`, both moved back along the odometry to each photo's step (at
        the least temperature)."""
        lr = np.zeros(len(poses))
        for odom, photo in self.history:
            back = se2_backward(np.r_[est[None], poses], odom, self.odom)
            self.lik.set_observation(photo, size)
            v = self.lik.ncc(back, size)
            lr += (v[1:] - v[0]) / self.T
        return lr

    def _remembered_rivals(self, est: np.ndarray, t: float, size: tuple[int, int]) -> bool:
        """Re-score the rivals found at earlier steps (moved by the odometry like the
        particles) and add this photo's log-likelihood ratio to the estimate to each one's
        running sum since it was found (a sequential likelihood-ratio test, Wald 1945: a
        rival must explain the photos along the drive, not one photo): those whose sum is
        still within `rival_nats` stay rivals (and rejoin the cloud), the others are dropped.
        A place the likelihood cannot tell from the estimate thus blocks the claim until
        the motion tells them apart, whether or not this step's uniform probes hit it."""
        c = self.config
        if not len(self.rivals):
            return False
        away = (np.hypot(*(self.rivals[:, :2] - est[:2]).T) > 2 * c.converged_m) | \
               (np.abs(wrap_angle(self.rivals[:, 2] - est[2])) > 2 * c.converged_rad)
        self.rivals, self.rival_lr = self.rivals[away], self.rival_lr[away]
        # each rival first climbs to the best of itself and six neighbours half a
        # tolerance away (it stands for a place, not for one pose that odometry noise moves)
        self.rivals, vr = self._climb(self.rivals, size)
        v = np.r_[self.lik.ncc(est[None], size), vr]
        lr = self.rival_lr + (v[1:] - v[0]) / self.T
        keep = np.flatnonzero(lr >= -c.rival_nats)
        keep = keep[np.argsort(-lr[keep])[: c.max_rivals]]
        self.rivals, self.rival_lr = self.rivals[keep], lr[keep]
        self._join(self.rivals, v[1:][keep] - v[0], t)
        return bool(len(self.rivals))

    def _join(self, poses: np.ndarray, dv: np.ndarray, t: float) -> None:
        """Add poses to the cloud, weighted as the heaviest particle times exp(dv / (T t))
        (dv: their NCC less the estimate's)."""
        if not len(poses):
            return
        pf = self.pf
        log_w = np.r_[pf.log_w, dv / (self.T * t) + pf.log_w.max()]
        pf.particles = np.r_[pf.particles, poses]
        pf.log_w = log_w - np.logaddexp.reduce(log_w)

    def mass_near(self, pose: np.ndarray) -> float:
        """The weight within the success tolerance of `pose`."""
        p, c = self.pf.particles, self.config
        near = (np.hypot(*(p[:, :2] - pose[:2]).T) < c.converged_m) & \
               (np.abs(wrap_angle(p[:, 2] - pose[2])) < c.converged_rad)
        return float(self.pf.weights[near].sum())

    def start_global(self) -> None:
        """Global localisation: uniform particles now, replaced at the next step by the
        photo's best poses when there is a search."""
        self.pf.init_uniform()
        self.seed_next = self.search is not None

    def _fresh(self, image: np.ndarray) -> np.ndarray:
        """`n_global` new particles: the photo's best poses (with a search), else uniform."""
        n = self.settings.n_global
        if self.search is None:
            return sample_free_poses(self.pf.free, n, self.pf.rng)
        return self._searched(image, n)

    def _searched(self, image: np.ndarray, n: int, n_cells: int | None = None) -> np.ndarray:
        """n poses (n, 3) from the search: half from the photo's best cells, half from the
        best cells of the track of the last `track_steps` photos along the odometry
        (`PanoramaIndex.track_scores`; all from the photo while there is no history). The
        photo alone is right at once after a kidnapping, whose track is stale for a few
        steps; the track where one photo fits many places alike. n_cells: draw among that
        many best cells (`PanoramaIndex.best_poses`)."""
        rng, track = self.pf.rng, (self.history + [(self.odom, image)])[-self.config.track_steps:]
        if len(track) < 2 or n < 2:
            return self.search.best_poses(image, n, rng, n_cells)[0]
        k = n // 2
        return np.r_[self.search.best_poses(image, k, rng, n_cells)[0],
                     self.search.best_poses(image, n - k, rng, n_cells, track)[0]]

    def _global_injection(self, image: np.ndarray) -> None:
        """Keep the current cloud (resampled to at most half the global count) and add
        `n_global` new particles (`_fresh`), all equally weighted; restart the averages."""
        pf = self.pf
        keep = min(len(pf.particles), self.settings.n_global // 2)
        idx = pf.rng.choice(len(pf.particles), keep, p=pf.weights)
        fresh = self._fresh(image)
        pf._set(np.r_[pf.particles[idx], fresh])
        pf.w_slow = pf.w_fast = 0.0
        self.converged, self.streak = False, 0
        self.rivals, self.rival_lr = np.zeros((0, 3)), np.zeros(0)
        self.history = []
