"""Structure from motion of unposed Strecha photos: the recovered camera layout matches the
ground-truth cameras up to a similarity."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from ibr.scene import load_scene
from ibr.proxy.sfm import SfmError, load_unposed


def _normalised_distances(centres: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    return d / d.mean()


@pytest.mark.realdata
def test_sfm_recovers_the_strecha_camera_layout(strecha_dir, tmp_path):
    names = ["0003.jpg", "0004.jpg", "0005.jpg", "0006.jpg", "0007.jpg"]
    (tmp_path / "images").mkdir()
    for n in names:
        Image.open(strecha_dir / "fountain-P11" / "images" / n).reduce(2).save(tmp_path / "images" / n)
    scene = load_unposed(tmp_path)
    assert sorted(v.name for v in scene) == names
    truth = load_scene(strecha_dir / "fountain-P11")
    est = np.array([scene.view(n).camera.center for n in names])
    gt = np.array([truth.view(n).camera.center for n in names])
    np.testing.assert_allclose(_normalised_distances(est), _normalised_distances(gt), atol=0.02)
    assert load_scene(tmp_path).cameras[0].width == 384     # the folder is now a COLMAP project


def test_sfm_without_photos_names_the_folder(tmp_path, ibrnav_command):
    (tmp_path / "images").mkdir()
    with pytest.raises(SfmError, match="no photos"):
        load_unposed(tmp_path)
    with pytest.raises(SfmError, match=str(tmp_path / "images")):
        ibrnav_command("sfm", tmp_path)
