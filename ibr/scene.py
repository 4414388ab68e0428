"""`Scene`: posed images (+ optional proxy mesh and points), and `load_scene(spec)`.

A spec is a path (a Strecha-format folder, a COLMAP model folder or a robot's capture
folder, `ibr.capture`) or
`synthetic:NAME[?seed=N&views=N&width=W&height=H]`; `parse_scene_spec` is the one reader of
that text, for every command. Every bad input raises one `SceneError` that names the
offending file or spec. Nothing downstream knows a file format.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from urllib.parse import parse_qsl

import numpy as np
import trimesh
from PIL import Image, UnidentifiedImageError

from ibr.camera import Camera, CameraError
from ibr.errors import InputError

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".ppm"}
MODEL_MESH = "mesh.ply"
"""A COLMAP model folder's mesh (`ibrnav export`, a capture's `model/`): the scene's mesh."""


class SceneError(InputError):
    """A scene that cannot be loaded; the message names the file and what is wrong."""


@dataclass(eq=False)
class View:
    """One posed photo: its camera (named after the image) and its pixels (H, W, 3) uint8."""

    camera: Camera
    image: np.ndarray
    path: Path | None = None

    @property
    def name(self) -> str:
        return self.camera.name


@dataclass(eq=False)
class Scene:
    """Posed images of one place.

    views: the photos. mesh: proxy or ground-truth geometry (world frame, metres) or None.
    points: (N, 3) world points (e.g. SfM) or None; point_colors (N, 3) uint8.
    root: the folder it came from, where derived data is cached (None for synthetic).
    world: the `SyntheticWorld` for synthetic scenes (floor plan, photographer), else None.
    """

    name: str
    views: list[View]
    mesh: trimesh.Trimesh | None = None
    points: np.ndarray | None = None
    point_colors: np.ndarray | None = None
    root: Path | None = None
    world: object | None = None
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.views)

    def __iter__(self):
        return iter(self.views)

    @property
    def cameras(self) -> list[Camera]:
        return [v.camera for v in self.views]

    def view(self, name: str) -> View:
        for v in self.views:
            if v.name == name:
                return v
        raise SceneError(f"scene {self.name!r} has no view {name!r}; it has "
                         f"{', '.join(v.name for v in self.views[:8])}{' ...' if len(self) > 8 else ''}")

    def without(self, name: str) -> "Scene":
        """The scene minus one view (for leave-one-out evaluation)."""
        self.view(name)
        return replace(self, views=[v for v in self.views if v.name != name])


def read_image(path: str | Path, expected_size: tuple[int, int] | None = None) -> np.ndarray:
    """Read an image file as (H, W, 3) uint8 RGB. Raises SceneError naming the file if it is
    missing, unreadable, truncated, or not `expected_size` (width, height)."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: image file not found")
    try:
        with Image.open(path) as im:
            im.load()  # decodes fully: a truncated file raises here
            rgb = np.asarray(im.convert("RGB"))
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as e:
        raise SceneError(f"{path}: unreadable or truncated image ({e})") from None
    if expected_size is not None and (rgb.shape[1], rgb.shape[0]) != tuple(expected_size):
        raise SceneError(f"{path}: image is {rgb.shape[1]}x{rgb.shape[0]} but its camera says "
                         f"{expected_size[0]}x{expected_size[1]}")
    return rgb


def load_strecha(folder: str | Path) -> Scene:
    """A Strecha-format folder: `images/NAME` with `cameras/NAME.camera` for each image."""
    folder = Path(folder)
    images = sorted(p for p in (folder / "images").iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise SceneError(f"{folder / 'images'}: no images found")
    views = []
    for img_path in images:
        cam_path = folder / "cameras" / f"{img_path.name}.camera"
        if not cam_path.is_file():
            raise SceneError(f"{cam_path}: camera file missing for image {img_path}")
        try:
            cam = Camera.from_strecha_file(cam_path, name=img_path.name)
        except CameraError as e:
            raise SceneError(str(e)) from None
        views.append(View(cam, read_image(img_path, (cam.width, cam.height)), img_path))
    return Scene(folder.name, views, root=folder)


def find_colmap_model(folder: Path) -> Path | None:
    """The folder holding cameras.bin/.txt: `folder`, `folder/sparse/0` or `folder/sparse`."""
    for cand in (folder, folder / "sparse" / "0", folder / "sparse"):
        if (cand / "cameras.bin").is_file() or (cand / "cameras.txt").is_file():
            return cand
    return None


# COLMAP camera models whose extra parameters map onto OpenCV distortion coefficients
_COLMAP_TO_OPENCV = {
    "SIMPLE_PINHOLE": lambda p: None,
    "PINHOLE": lambda p: None,
    "SIMPLE_RADIAL": lambda p: np.array([p[3], 0, 0, 0]),
    "RADIAL": lambda p: np.array([p[3], p[4], 0, 0]),
    "OPENCV": lambda p: np.array(p[4:8]),
}


def load_colmap(folder: str | Path, image_dir: str | Path | None = None) -> Scene:
    """A COLMAP sparse model (through pycolmap) with its images; distorted images are
    undistorted to the model's pinhole K. Images are looked for in `image_dir`, else
    `folder/images`, else the model folder's parents' `images/`."""
    import cv2
    import pycolmap

    folder = Path(folder)
    model = find_colmap_model(folder)
    if model is None:
        raise SceneError(f"{folder}: no COLMAP model (cameras.bin/txt) here or in sparse/0")
    try:
        rec = pycolmap.Reconstruction(str(model))
    except Exception as e:  # pycolmap raises its own errors for corrupt files
        raise SceneError(f"{model}: unreadable COLMAP model ({e})") from None
    candidates = [Path(image_dir)] if image_dir else [folder / "images",
                                                      *[p / "images" for p in list(model.parents)[:3]]]
    img_root = next((c for c in candidates if c.is_dir()), None)
    if img_root is None:
        raise SceneError(f"{folder}: no images/ folder found for the COLMAP model in {model}")
    views = []
    for image_id in sorted(rec.reg_image_ids()):
        image = rec.image(image_id)
        cam_model = image.camera.model_name
        if cam_model not in _COLMAP_TO_OPENCV:
            raise SceneError(f"{model}: camera model {cam_model} of image {image.name} is not "
                             f"supported; use one of {sorted(_COLMAP_TO_OPENCV)}")
        try:
            cam = Camera.from_pycolmap(image)
        except CameraError as e:
            raise SceneError(f"{model}: {e}") from None
        rgb = read_image(img_root / image.name, (cam.width, cam.height))
        dist = _COLMAP_TO_OPENCV[cam_model](list(image.camera.params))
        if dist is not None and np.any(dist != 0):
            rgb = cv2.undistort(rgb, cam.K, dist)
        views.append(View(cam, rgb, img_root / image.name))
    if not views:
        raise SceneError(f"{model}: the COLMAP model has no registered images")
    pts = rec.points3D
    xyz = np.array([p.xyz for p in pts.values()]).reshape(-1, 3)
    rgb = np.array([p.color for p in pts.values()], dtype=np.uint8).reshape(-1, 3)
    mesh_path = next((m / MODEL_MESH for m in (model, folder) if (m / MODEL_MESH).is_file()), None)
    mesh = trimesh.load(mesh_path, process=False, force="mesh") if mesh_path is not None else None
    return Scene(folder.name, views, mesh=mesh, points=xyz, point_colors=rgb, root=folder)


def load_capture(folder: str | Path, refine: bool = False, use_model: bool = True) -> Scene:
    """A robot's capture-session folder (`ibr.capture` reads its layout): its final model
    (`model/`: COLMAP model and mesh) when the mission wrote one and `use_model`, else every
    photo at the filter's logged pose with the mission's last map (mesh and points) when
    there is one.
    `refine`: pycolmap triangulation with the poses fixed, then bundle adjustment
    (`ibr.proxy.refine`); how far the poses moved is `scene.meta["refinement"]`.
    `scene.meta["poses"]`: "model" or "filter", "+ refined" when refined."""
    from ibr.capture import PHOTOS, read_capture

    cap = read_capture(folder)
    if use_model and cap.model is not None:
        loaded = load_colmap(cap.model, cap.folder / PHOTOS)
        views = [replace(v, camera=v.camera.with_pose(v.camera.cam_from_world, Path(v.name).stem))
                 for v in loaded]
        scene = replace(loaded, name=cap.folder.name, views=views, root=cap.folder, meta={"poses": "model"})
    else:
        views = [View(cam, read_image(cap.folder / r["file"], cap.image_size), cap.folder / r["file"])
                 for cam, r in zip(cap.photo_cameras(), cap.photos)]
        scene = Scene(cap.folder.name, views, root=cap.folder, meta={"poses": "filter"})
        last = cap.last_map()
        if last is not None:
            scene.mesh, scene.points, scene.point_colors = last
            scene.meta["map"] = cap.maps[-1].name
    scene.meta["session"] = cap.meta
    return refine_scene(scene) if refine else scene


def refine_scene(scene: Scene) -> Scene:
    """The scene with its poses refined by `ibr.proxy.refine.refine_poses` (triangulate with
    the poses fixed, then bundle-adjust), its points the refined ones; the report of how far
    the poses moved is `meta["refinement"]`. The mesh is kept (it was built on the old poses)."""
    from ibr.proxy.refine import refine_poses

    result = refine_poses(scene.cameras, [v.image for v in scene.views])
    views = [replace(v, camera=c) for v, c in zip(scene.views, result.cameras)]
    meta = {**scene.meta, "poses": f"{scene.meta.get('poses', 'given')} + refined",
            "refinement": result.report()}
    return replace(scene, views=views, points=result.points, point_colors=result.colors, meta=meta)


SYNTHETIC_PARAMS = ("seed", "views", "width", "height")


@dataclass(frozen=True)
class SceneSpec:
    """A parsed SCENE argument. `world`: the synthetic world's name (None for a path);
    `params`: its integer query parameters (a subset of SYNTHETIC_PARAMS); `path`: the
    folder of a real scene (None for a synthetic one); `text`: the spec as given."""

    text: str
    world: str | None = None
    params: dict = field(default_factory=dict)
    path: Path | None = None

    def seed(self, default: int = 0) -> int:
        """The world seed: `?seed=N` when the spec gives one, else `default`."""
        return self.params.get("seed", default)


def parse_scene_spec(spec: str | Path, synthetic_only: bool = False,
                     allowed: tuple[str, ...] = SYNTHETIC_PARAMS) -> SceneSpec:
    """Read SCENE: `synthetic:NAME[?seed=N&views=N&width=W&height=H]` or a scene folder's
    path. `synthetic_only`: a path is an error (the command needs a world it can simulate);
    `allowed`: the query parameters the caller uses (others are an error, not silently
    ignored). Raises SceneError naming the spec; checks only the text, not the folder."""
    from ibr.synthetic import WORLDS

    s = str(spec)
    if not s.startswith("synthetic:"):
        if synthetic_only:
            raise SceneError(f"{s}: this command needs a synthetic world, synthetic:NAME[?seed=N] with NAME "
                             f"in {sorted(WORLDS)}")
        return SceneSpec(s, path=Path(s))
    name, _, query = s.split(":", 1)[1].partition("?")
    try:
        params = {k: int(v) for k, v in parse_qsl(query, strict_parsing=bool(query))}
    except ValueError:
        raise SceneError(f"{s}: bad query; expected integers, e.g. synthetic:office?seed=1") from None
    unknown = set(params) - set(allowed)
    if unknown or name not in WORLDS:
        query_help = "&".join(f"{k}=N" for k in allowed)
        raise SceneError(f"{s}: expected synthetic:NAME[?{query_help}] with NAME in {sorted(WORLDS)}")
    return SceneSpec(s, world=name, params=params)


def load_synthetic(spec: str | SceneSpec) -> Scene:
    """`synthetic:NAME[?seed=N&views=N&width=W&height=H]`: photos of a synthetic world
    from its default cameras; the ground-truth mesh is the scene's mesh."""
    from ibr.synthetic import make_world

    spec = spec if isinstance(spec, SceneSpec) else parse_scene_spec(spec, synthetic_only=True)
    params = spec.params
    world = make_world(spec.world, spec.seed())
    n = params["views"] if "views" in params else world.default_view_count()
    cams = world.default_cameras(n, params.get("width", 640), params.get("height", 480))
    views = [View(c, world.photograph(c)) for c in cams]
    return Scene(f"synthetic:{spec.world}", views, mesh=world.mesh, world=world,
                 meta={"seed": world.seed})


def load_scene(spec: str | Path, refine: bool = False) -> Scene:
    """Load a scene from a path (Strecha folder, COLMAP model folder or a robot's capture
    folder) or a `synthetic:NAME[?seed=N]` spec. `refine`: bundle-adjust the poses first
    (`refine_scene`). Raises SceneError naming the bad input."""
    parsed = parse_scene_spec(spec)
    if parsed.world is not None:
        scene = load_synthetic(parsed)
        return refine_scene(scene) if refine else scene
    path = parsed.path
    if not path.exists():
        raise SceneError(f"{path}: no such scene folder (or use synthetic:office)")
    from ibr.capture import is_capture_folder

    if is_capture_folder(path):
        return load_capture(path, refine)
    if (path / "cameras").is_dir() and (path / "images").is_dir():
        scene = load_strecha(path)
    elif find_colmap_model(path) is not None:
        scene = load_colmap(path)
    else:
        raise SceneError(f"{path}: not a scene folder; expected images/ + cameras/ (Strecha), a "
                         "COLMAP model (cameras.bin, images.bin, points3D.bin, here or in sparse/0) or a "
                         "capture folder (session.json, log.jsonl, photos/)")
    return refine_scene(scene) if refine else scene
