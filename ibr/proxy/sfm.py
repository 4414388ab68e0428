"""Structure from motion for photos without poses, through pycolmap: SIFT features, exhaustive
matching and COLMAP's incremental mapping (the role Bundler plays in Foster, Wang & Grupen,
section IV-B). The model is written in COLMAP's layout beside the photos, so `load_scene`
reads the folder afterwards like any COLMAP project:

    FOLDER/images/*.jpg   ->   FOLDER/sparse/0/{cameras,images,points3D}.bin
                               FOLDER/.ibrnav_cache/sfm/database.db

The reconstruction's frame and scale are arbitrary (COLMAP's), not metres.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from ibr.colmap import colmap_errors_only, import_in_name_order
from ibr.errors import InputError
from ibr.scene import IMAGE_SUFFIXES, Scene, load_colmap


class SfmError(InputError):
    """The photos could not be reconstructed (none found, or too few registered)."""


@dataclass(frozen=True)
class SfmConfig:
    """Settings of `reconstruct`."""

    single_camera: bool = True
    """All photos share one camera (intrinsics estimated once)."""
    min_registered: int = 3
    """Fewest photos the largest reconstruction must register."""
    seed: int = 0
    """Seed of COLMAP's pair verification and mapping. With the photos numbered in name order
    it makes a run repeatable, except where COLMAP's threads differ: the CPU index matcher
    now and then matches a pair otherwise, and an adjustment of a large model sums in
    another order (the mission's SfM, `robot.mission.map_building.MapConfig.mapping_threads`,
    runs both on one thread; here the user's photos, often 3,000 px wide, keep COLMAP's
    threads)."""


def reconstruct(folder: str | Path, cfg: SfmConfig = SfmConfig(), overwrite: bool = False) -> Path:
    """Reconstruct `folder/images` and write the largest model to `folder/sparse/0`; reuse it
    when present unless `overwrite`. Returns the model folder. Seeded (`SfmConfig.seed`)
    and numbered in name order."""
    import pycolmap

    folder = Path(folder)
    images = folder / "images"
    if not images.is_dir() or not any(p.suffix.lower() in IMAGE_SUFFIXES for p in images.iterdir()):
        raise SfmError(f"{images}: no photos to reconstruct")
    model = folder / "sparse" / "0"
    if (model / "cameras.bin").is_file() and not overwrite:
        return model
    work = folder / ".ibrnav_cache" / "sfm"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    db = work / "database.db"
    mode = pycolmap.CameraMode.SINGLE if cfg.single_camera else pycolmap.CameraMode.AUTO
    verify = pycolmap.TwoViewGeometryOptions()
    verify.ransac.random_seed = cfg.seed
    mapping = pycolmap.IncrementalPipelineOptions()
    mapping.random_seed = mapping.mapper.random_seed = cfg.seed
    with colmap_errors_only():
        import_in_name_order(db, images, mode)
        pycolmap.extract_features(db, images, camera_mode=mode, device=pycolmap.Device.cpu)
        pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu, verification_options=verify)
        maps = pycolmap.incremental_mapping(db, images, work / "sparse", mapping)
    if not maps:
        raise SfmError(f"{images}: COLMAP could not register the photos (too little overlap?)")
    best = max(maps.values(), key=lambda r: r.num_reg_images())
    if best.num_reg_images() < cfg.min_registered:
        raise SfmError(f"{images}: only {best.num_reg_images()} photos registered; need {cfg.min_registered}")
    model.mkdir(parents=True, exist_ok=True)
    best.write(model)
    return model


def load_unposed(folder: str | Path, cfg: SfmConfig = SfmConfig()) -> Scene:
    """The scene of the photos in `folder/images`, posed by `reconstruct`."""
    model = reconstruct(folder, cfg)
    return load_colmap(model, Path(folder) / "images")
