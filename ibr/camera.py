"""The one camera type of ibrnav: pinhole intrinsics K, image size and `cam_from_world`.

Conventions (docs/ARCHITECTURE.md): camera axes are OpenCV's (x right, y down, z forward); pixel
(u, v) = (0, 0) is the *centre* of the top-left pixel; metres and radians. Every function
about views takes `Camera` objects. Conversions live here, each in one place:
from and to pycolmap, from/to Strecha `.camera` files and to OpenGL (`gl_projection`, the only
code that knows GL's clip-space conventions). The conversion to rerun is `ibr.viz.camera_archetypes`
(algorithm code does not import rerun).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ibr.errors import InputError


class CameraError(InputError):
    """A camera that cannot be used: bad shape, non-finite numbers, bad file."""


def _as_matrix(a, shape: tuple[int, int], what: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape != shape:
        raise CameraError(f"{what} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CameraError(f"{what} contains NaN or infinite values:\n{a}")
    return a


def intrinsics_from_fov(fov_x_deg: float, width: int, height: int) -> np.ndarray:
    """K (3, 3) of a square-pixel camera with horizontal field of view `fov_x_deg` (degrees)
    and the principal point at the image centre (pixel-centre convention)."""
    f = 0.5 * width / np.tan(0.5 * np.radians(fov_x_deg))
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])


def rigid(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from a 3x3 rotation and a 3-vector translation."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def invert_rigid(T: np.ndarray) -> np.ndarray:
    """Inverse of a 4x4 rigid transform (rotation + translation), exact."""
    R, t = T[:3, :3], T[:3, 3]
    return rigid(R.T, -R.T @ t)


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera.

    Attributes
    ----------
    K : (3, 3) intrinsics in pixels (fx, fy, cx, cy; skew allowed).
    width, height : image size in pixels.
    cam_from_world : (4, 4) rigid transform taking world points (metres) to camera axes.
    name : optional label (the image name for a scene's view).
    """

    K: np.ndarray
    width: int
    height: int
    cam_from_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    name: str = ""

    def __post_init__(self):
        object.__setattr__(self, "K", _as_matrix(self.K, (3, 3), f"K of camera {self.name!r}"))
        T = _as_matrix(self.cam_from_world, (4, 4), f"cam_from_world of camera {self.name!r}")
        R = T[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise CameraError(f"cam_from_world of camera {self.name!r} is not a rotation:\n{R}")
        object.__setattr__(self, "cam_from_world", T)
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise CameraError(f"camera {self.name!r} has size {self.width}x{self.height}")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    # --- construction -------------------------------------------------------------
    @classmethod
    def look_at(cls, eye, target, K, width: int, height: int, up=(0, 0, 1), name: str = ""):
        """Camera at `eye` looking at `target` (world, metres) with image 'up' along `up`."""
        eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
        z = target - eye
        if np.linalg.norm(z) < 1e-12:
            raise CameraError("look_at: eye and target coincide")
        z /= np.linalg.norm(z)
        x = np.cross(z, up)
        if np.linalg.norm(x) < 1e-9:  # looking along `up`: any right vector will do
            x = np.cross(z, [1.0, 0, 0]) if abs(z[0]) < 0.9 else np.cross(z, [0, 1.0, 0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        world_from_cam = rigid(np.stack([x, y, z], axis=1), eye)
        return cls(K, width, height, invert_rigid(world_from_cam), name)

    @classmethod
    def from_pycolmap(cls, image, camera=None) -> "Camera":
        """From a registered `pycolmap.Image` (and its `pycolmap.Camera`).

        Only the pinhole part is kept; undistorting images is the COLMAP loader's job.
        COLMAP puts pixel (0, 0) at the top-left pixel's *corner*, ibrnav at its centre, so
        the principal point moves by half a pixel (`to_pycolmap` adds it back)."""
        camera = camera if camera is not None else image.camera
        pose = image.cam_from_world()
        T = np.eye(4)
        T[:3, :] = pose.matrix()
        K = camera.calibration_matrix().copy()
        K[:2, 2] -= 0.5
        return cls(K, camera.width, camera.height, T, image.name)

    def to_pycolmap(self, camera_id: int = 1):
        """This camera's intrinsics as a `pycolmap.Camera` (PINHOLE; skew dropped), in
        COLMAP's pixel convention (principal point + 0.5, see `from_pycolmap`)."""
        import pycolmap

        K = self.K
        return pycolmap.Camera(model="PINHOLE", width=self.width, height=self.height, camera_id=camera_id,
                               params=[K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5])

    @classmethod
    def from_strecha_file(cls, path: str | Path, name: str = "") -> "Camera":
        """Read a Strecha `.camera` file: K (3 rows), radial distortion (1 row), R (3 rows,
        columns are the camera axes in the world), C (camera centre), "width height"."""
        path = Path(path)
        try:
            rows = [r.split() for r in path.read_text().splitlines() if r.strip()]
            if len(rows) < 9 or any(len(r) != 3 for r in rows[:8]):
                raise ValueError("expected 8 rows of 3 numbers, then 'width height'")
            v = np.array([float(x) for r in rows[:8] for x in r])
            K, R, C = v[:9].reshape(3, 3), v[12:21].reshape(3, 3), v[21:24]
            width, height = (int(float(x)) for x in rows[8][:2])
        except (ValueError, IndexError, OSError) as e:
            raise CameraError(f"{path}: not a Strecha camera file ({e})") from None
        try:
            return cls(K, width, height, rigid(R.T, -R.T @ C), name or path.name)
        except CameraError as e:
            raise CameraError(f"{path}: {e}") from None

    def to_strecha_text(self) -> str:
        """The Strecha `.camera` text of this camera (no distortion)."""
        R, C = self.world_from_cam[:3, :3], self.center
        rows = [*self.K, [0, 0, 0], *R, C]
        body = "\n".join(" ".join(f"{x:.12g}" for x in r) for r in rows)
        return f"{body}\n{self.width} {self.height}\n"

    def scaled(self, s: float) -> "Camera":
        """Same view at `s` times the resolution (pixel-centre convention kept exact)."""
        S = np.diag([s, s, 1.0])
        S[:2, 2] = 0.5 * s - 0.5  # u' = s (u + 0.5) - 0.5
        w, h = max(1, round(self.width * s)), max(1, round(self.height * s))
        return Camera(S @ self.K, w, h, self.cam_from_world, self.name)

    def with_pose(self, cam_from_world: np.ndarray, name: str | None = None) -> "Camera":
        """Same intrinsics, another pose."""
        return Camera(self.K, self.width, self.height, cam_from_world,
                      self.name if name is None else name)

    # --- geometry -----------------------------------------------------------------
    @property
    def world_from_cam(self) -> np.ndarray:
        return invert_rigid(self.cam_from_world)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates (metres), shape (3,)."""
        return self.world_from_cam[:3, 3]

    @property
    def forward(self) -> np.ndarray:
        """Optical axis (+z of the camera) in world coordinates, unit (3,)."""
        return self.cam_from_world[2, :3].copy()

    def to_camera_frame(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points -> (N, 3) points in camera axes."""
        p = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        return p @ self.cam_from_world[:3, :3].T + self.cam_from_world[:3, 3]

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project (N, 3) world points. Returns pixels (N, 2) as (u, v) and depth (N,),
        the camera-z in metres (<= 0 means behind the camera; its pixels are meaningless)."""
        pc = self.to_camera_frame(points_world)
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uvw = pc @ self.K.T
            uv = uvw[:, :2] / uvw[:, 2:3]
        return uv, z

    def in_image(self, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(N,) bool: which of a `project` result's pixels `uv` (N, 2), at camera-z `z` (N,),
        are in front of the camera and inside its image, [0, width) x [0, height)."""
        with np.errstate(invalid="ignore"):
            return (z > 0) & np.all(uv >= 0, axis=1) & (uv[:, 0] < self.width) & (uv[:, 1] < self.height)

    def unproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) at camera-z `depth` (N,) metres -> world points (N, 3)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        rays = np.c_[uv, np.ones(len(uv))] @ np.linalg.inv(self.K).T  # z = 1
        pc = rays * np.asarray(depth, dtype=np.float64).reshape(-1, 1)
        return pc @ self.world_from_cam[:3, :3].T + self.center

    def ray_directions(self, uv: np.ndarray) -> np.ndarray:
        """Unit world-frame directions (N, 3) of the rays through pixels `uv` (N, 2)."""
        d = self.unproject(uv, np.ones(len(np.asarray(uv).reshape(-1, 2)))) - self.center
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def pixel_grid(self) -> np.ndarray:
        """(H*W, 2) pixel centres (u, v) in row-major order."""
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        return np.c_[u.ravel(), v.ravel()].astype(np.float64)

    # --- OpenGL: the only place that knows its conventions -------------------------
    def gl_projection(self, near: float = 0.05, far: float = 1000.0) -> np.ndarray:
        """4x4 matrix from *camera axes* (OpenCV) to GL clip space.

        Window x = u + 0.5 and window y = v + 0.5, so a framebuffer read back with
        `fbo.read()` (row 0 first) is already an image in row-major (v, u) order: no flip.
        Depth maps near -> -1, far -> +1 in NDC. Triangle winding is mirrored by the
        y mapping, so renderers disable face culling.
        """
        (fx, s, cx), (_, fy, cy) = self.K[0], self.K[1]
        W, H = self.width, self.height
        P = np.zeros((4, 4))
        P[0] = [2 * fx / W, 2 * s / W, 2 * (cx + 0.5) / W - 1, 0]
        P[1] = [0, 2 * fy / H, 2 * (cy + 0.5) / H - 1, 0]
        P[2] = [0, 0, (far + near) / (far - near), -2 * far * near / (far - near)]
        P[3] = [0, 0, 1, 0]
        return P

    def gl_clip_from_world(self, near: float = 0.05, far: float = 1000.0) -> np.ndarray:
        """4x4 world -> clip matrix (`gl_projection @ cam_from_world`), row-major float64.
        Upload to GLSL as `.T.astype('f4')` (GLSL is column-major)."""
        return self.gl_projection(near, far) @ self.cam_from_world

    def __repr__(self) -> str:
        c = np.array2string(self.center, precision=3)
        return f"Camera({self.name!r}, {self.width}x{self.height}, f={self.K[0, 0]:.1f}, center={c})"
