"""Pose refinement of posed photos with pycolmap: triangulate with the poses fixed, then
bundle-adjust the poses and points together, and say how far the poses moved.

A robot's capture session poses its photos with its particle filter (odometry, compass,
PnP fixes): good to a few centimetres and degrees, not to a pixel. COLMAP's point
triangulator (SIFT features, exhaustive matching with geometric verification, then
triangulation against the fixed poses; Schoenberger & Frahm 2016, section 4.5) gives tracks
on those poses; a global bundle adjustment (intrinsics fixed) then moves poses and points to
minimise the reprojection error (a Cauchy loss; observations it cannot explain are dropped
and the adjustment repeated, as COLMAP's global refinement does). The adjustment's gauge is
held by the two cameras furthest apart, and the result is mapped back onto the given poses
by the similarity that best aligns all cameras' orientations and centres (`align_frames`):
the world frame, its scale and its floor stay the given ones, and what moved is the
disagreement between the photos and their poses.

Units: metres, degrees in the report; reprojection errors in pixels.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibr.camera import Camera
from ibr.errors import InputError


class RefineError(InputError):
    """The photos gave too few tracks to refine their poses; the message says how many."""


@dataclass(frozen=True)
class RefineConfig:
    """Settings of `refine_poses`."""

    min_points: int = 50
    """Fewer triangulated points than this: no refinement (`RefineError`), not a guess."""
    min_observations: int = 20
    """A camera observing fewer triangulated points than this is left where it was (too
    weakly constrained to move); it is named in the report. A count, not a length."""
    max_iterations: int = 200
    """Iterations of each bundle adjustment."""
    rounds: int = 3
    """Bundle adjustments, each followed by dropping the observations it cannot explain
    (COLMAP's iterative global refinement)."""
    max_error_px: float = 4.0
    """Observations reprojecting further than this (pixels, COLMAP's default) are dropped
    between rounds: a property of feature measurement, not of the scene."""
    min_angle_deg: float = 1.5
    """Points triangulated under a smaller angle are dropped between rounds (COLMAP's default)."""
    loss_scale_px: float = 1.0
    """Scale of the Cauchy loss on reprojection errors (pixels): a wrong match pulls little."""
    """Iterations of the global bundle adjustment."""


@dataclass
class Refinement:
    """The refined cameras (same order and names), the triangulated points (N, 3) world metres
    with colours (N, 3) uint8, how far each camera moved (moved_m (N,) metres, turned_deg (N,)
    degrees), the mean reprojection error (pixels) after triangulation and after adjustment,
    and the cameras left unrefined (too few observations)."""

    cameras: list[Camera]
    points: np.ndarray
    colors: np.ndarray
    moved_m: np.ndarray
    turned_deg: np.ndarray
    error_before_px: float
    error_after_px: float
    unconstrained: list[str]

    def moved_far(self, factor: float = 5.0) -> list[str]:
        """Cameras that moved more than `factor` times the median camera movement (in metres
        or degrees; a ratio, so scale-free): worth a look, since a camera with a few wrong
        matches can be pulled off while its reprojection error stays small."""
        far = ((self.moved_m > factor * np.median(self.moved_m))
               | (self.turned_deg > factor * np.median(self.turned_deg)))
        return [c.name for c, f in zip(self.cameras, far) if f]

    def report(self) -> dict:
        """How far the poses moved: median and max, metres and degrees; errors in pixels;
        the cameras left as given (`unconstrained`) and those that moved far (`moved_far`)."""
        return {"cameras": len(self.cameras), "points": len(self.points),
                "moved_m_median": float(np.median(self.moved_m)), "moved_m_max": float(self.moved_m.max()),
                "turned_deg_median": float(np.median(self.turned_deg)),
                "turned_deg_max": float(self.turned_deg.max()),
                "reprojection_px_before": self.error_before_px, "reprojection_px_after": self.error_after_px,
                "unconstrained": self.unconstrained, "moved_far": self.moved_far()}


def align_frames(ba_from_cam: np.ndarray, world_from_cam: np.ndarray, rounds: int = 3
                 ) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (s, R, t), world = s R ba + t, that best maps the bundle adjustment's
    frame onto the given one, from N cameras' poses in both ((N, 4, 4) each). The rotation
    is the chordal mean of the per-camera rotations (a rotation average: camera centres
    alone leave it undetermined when the robot drove in a line); the scale starts as the
    median ratio of pairwise centre distances and the translation as the median offset, so
    a few cameras the adjustment moved far do not pull the frame; then scale and translation
    are refitted `rounds` times by least squares (Umeyama 1991, eqs. 41-42, with R given) on
    the cameras within three times the median centre residual."""
    src, dst = ba_from_cam[:, :3, 3], world_from_cam[:, :3, 3]
    per_camera = world_from_cam[:, :3, :3] @ np.transpose(ba_from_cam[:, :3, :3], (0, 2, 1))
    U, _, Vt = np.linalg.svd(per_camera.sum(axis=0))
    R = U @ np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    i, j = np.triu_indices(len(src), 1)
    d_src = np.linalg.norm(src[i] - src[j], axis=1)
    ok = d_src > 0
    s = float(np.median(np.linalg.norm(dst[i] - dst[j], axis=1)[ok] / d_src[ok])) if ok.any() else 1.0
    t = np.median(dst - s * src @ R.T, axis=0)
    for _ in range(rounds):
        res = np.linalg.norm(s * src @ R.T + t - dst, axis=1)
        keep = res <= 3 * np.median(res) + 1e-12
        a, b = src[keep] - src[keep].mean(0), dst[keep] - dst[keep].mean(0)
        if np.sum(a * a) > 0:
            s = float(np.sum((a @ R.T) * b) / np.sum(a * a))
        t = dst[keep].mean(0) - s * R @ src[keep].mean(0)
    return s, R, t


def _triangulate(cameras: list[Camera], images: list[np.ndarray], work: Path):
    """COLMAP's point triangulator on the fixed poses: features, exhaustive matching, tracks."""
    import pycolmap
    from PIL import Image

    from ibr.colmap import colmap_errors_only

    img_dir = work / "images"
    img_dir.mkdir()
    names = [f"{i:05d}.png" for i in range(len(cameras))]
    for name, image in zip(names, images):
        Image.fromarray(image).save(img_dir / name)
    db_path = work / "database.db"
    with colmap_errors_only():
        pycolmap.extract_features(db_path, img_dir, names, camera_mode=pycolmap.CameraMode.PER_IMAGE,
                                  device=pycolmap.Device.cpu)
        pycolmap.match_exhaustive(db_path, device=pycolmap.Device.cpu)
        rec = pycolmap.Reconstruction()
        db = pycolmap.Database.open(db_path)
        index = {}
        for im in db.read_all_images():
            i = names.index(im.name)
            cam = cameras[i].to_pycolmap(im.camera_id)
            db.update_camera(cam)  # the database's guessed intrinsics are replaced by the known ones
            rec.add_camera_with_trivial_rig(cam)
            rec.add_image_with_trivial_frame(pycolmap.Image(name=im.name, camera_id=im.camera_id,
                                                            image_id=im.image_id),
                                             pycolmap.Rigid3d(cameras[i].cam_from_world[:3, :]))
            index[im.image_id] = i
        db.close()
        (work / "triangulated").mkdir()
        rec = pycolmap.triangulate_points(rec, db_path, img_dir, work / "triangulated", refine_intrinsics=False)
    return rec, index


def refine_poses(cameras: list[Camera], images: list[np.ndarray], config: RefineConfig = RefineConfig()
                 ) -> Refinement:
    """Refine the poses of posed photos (`cameras`, `images` (H, W, 3) uint8): triangulate
    with the poses fixed, bundle-adjust poses and points (intrinsics fixed), map the result
    back onto the given frame (similarity on the camera centres). Raises RefineError when
    the photos give fewer than `config.min_points` points."""
    import pycolmap

    from ibr.colmap import colmap_errors_only

    work = Path(tempfile.mkdtemp(prefix="ibrnav_refine_"))
    try:
        rec, index = _triangulate(cameras, images, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if rec.num_points3D() < config.min_points:
        raise RefineError(f"{len(cameras)} photos gave {rec.num_points3D()} triangulated points on their poses; "
                          f"refining needs {config.min_points} (too little overlap, or poses far off)")
    before = rec.compute_mean_reprojection_error()
    options = pycolmap.BundleAdjustmentOptions(refine_focal_length=False, refine_principal_point=False,
                                               refine_extra_params=False)
    options.ceres.solver_options.max_num_iterations = config.max_iterations
    options.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    options.ceres.loss_function_scale = config.loss_scale_px
    with colmap_errors_only():
        for _ in range(config.rounds):
            pycolmap.create_default_bundle_adjuster(options, _gauge_config(rec), rec).solve()
            rec.update_point_3d_errors()  # the adjustment leaves the points' stored errors as they were
            pycolmap.ObservationManager(rec).filter_all_points3D(config.max_error_px, config.min_angle_deg)
    after = rec.compute_mean_reprojection_error()
    return _aligned_result(cameras, rec, index, before, after, config)


def _gauge_config(rec):
    """Adjust every image, with the gauge fixed by holding the two cameras furthest apart
    (their poses as given): COLMAP's default fixes one camera and one coordinate of the
    next, which leaves the scale nearly free when the robot took several photos from one
    spot, and the adjustment can then collapse. `align_frames` afterwards spreads the two
    cameras' own pose errors over all cameras."""
    import pycolmap

    config = pycolmap.BundleAdjustmentConfig()
    ids = sorted(rec.reg_image_ids())
    for i in ids:
        config.add_image(i)
    centres = np.array([rec.image(i).projection_center() for i in ids])
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    a, b = np.unravel_index(np.argmax(d), d.shape)
    for k in (a, b):
        config.set_constant_rig_from_world_pose(rec.image(ids[k]).frame_id)
    return config


def _aligned_result(cameras: list[Camera], rec, index: dict[int, int], before: float, after: float,
                    config: RefineConfig) -> Refinement:
    """Refined cameras mapped onto the given frame, with how far each moved."""
    adjusted: dict[int, np.ndarray] = {}
    for image_id, i in index.items():
        image = rec.image(image_id)
        if image.has_pose and image.num_points3D >= config.min_observations:
            T = np.eye(4)
            T[:3, :] = image.cam_from_world().matrix()
            adjusted[i] = T
    ids = sorted(adjusted)
    if len(ids) < 2:
        raise RefineError(f"bundle adjustment kept {len(ids)} of {len(cameras)} cameras with at least "
                          f"{config.min_observations} observations ({rec.num_points3D()} points left, mean "
                          f"error {after:.3g} px); no pose was refined")
    s, R, t = align_frames(np.array([np.linalg.inv(adjusted[i]) for i in ids]),
                           np.array([cameras[i].world_from_cam for i in ids]))
    world_from_ba = np.eye(4)
    world_from_ba[:3, :3], world_from_ba[:3, 3] = R, t
    out, moved, turned = [], np.zeros(len(cameras)), np.zeros(len(cameras))
    for i, cam in enumerate(cameras):
        if i not in adjusted:
            out.append(cam)
            continue
        T = adjusted[i].copy()
        T[:3, 3] *= s  # scale the BA frame to metres, then move it onto the given world
        new = cam.with_pose(T @ np.linalg.inv(world_from_ba))
        moved[i] = np.linalg.norm(new.center - cam.center)
        dR = new.cam_from_world[:3, :3] @ cam.cam_from_world[:3, :3].T
        turned[i] = np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
        out.append(new)
    pts = rec.points3D.values()
    xyz = np.array([p.xyz for p in pts]).reshape(-1, 3)
    cols = np.array([p.color for p in pts], np.uint8).reshape(-1, 3)
    return Refinement(out, s * xyz @ R.T + t, cols, moved, turned, float(before), float(after),
                      [cameras[i].name for i in range(len(cameras)) if i not in adjusted])
