"""Fixtures shared by the ibr tests: textured test geometry."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image


def _textured(mesh: trimesh.Trimesh, seed: int) -> trimesh.Trimesh:
    """`mesh` with a random blocky texture mapped by its x and z coordinates."""
    rng = np.random.default_rng(seed)
    tex = np.kron(rng.integers(0, 256, (48, 48, 3)), np.ones((6, 6, 1))).astype(np.uint8)
    v = mesh.vertices
    uv = (v[:, [0, 2]] - v[:, [0, 2]].min(0)) / np.ptp(v[:, [0, 2]], axis=0).max()
    material = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(tex))
    return trimesh.Trimesh(v, mesh.faces, visual=trimesh.visual.TextureVisuals(uv, material=material),
                           process=False)


@pytest.fixture(scope="session")
def textured():
    """`_textured(mesh, seed)`: a mesh with a random blocky texture (plane sweep, light field)."""
    return _textured
