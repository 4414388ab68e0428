"""`ibrnav eval-capture SESSION --json OUT`: what a capture is for, new views. The final
model of a capture session (`model/`: COLMAP poses, the photos, `mesh.ply`) is rendered with
ULR at random robot poses in the world's free space (camera height and mount of the
session's robot, random headings) and compared with the synthetic world's true renders
(`robot.mission.evaluation.eval_capture`): PSNR / SSIM / covered fraction, mean and worst
decile. The world is the one the session's meta names (`ibrnav demo` records `world` and
`seed`), or `--world synthetic:NAME?seed=N`. By default the poses are those `ibrnav explore
--json` draws for the same seed (`eval_capture` in its report), so a demo's capture and
explore's random and adaptive ones are judged on the same views."""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np

from ibr.errors import InputError
from ibrnav import jsonout, recording

log = logging.getLogger(__name__)
METHODS = {"ulr": "field", "ulr-pixel": "pixel"}
"""--method -> `UlrConfig.blending`: Buehler's sparse blending field (what the mission's tour
and `explore --json` render with) or per-pixel weights (the quality reference)."""


class EvalCaptureError(InputError):
    """A session or flag `ibrnav eval-capture` cannot use; names the folder or flag."""


def session_folder(path: str | Path) -> Path:
    """The capture session folder `path` names: the folder itself, or the session whose
    `model/` folder it is."""
    from ibr.capture import MODEL, is_capture_folder

    path = Path(path)
    if is_capture_folder(path):
        return path
    if path.name == MODEL and is_capture_folder(path.parent):
        return path.parent
    raise EvalCaptureError(f"{path}: not a capture session folder (no session.json; `ibrnav demo --session DIR` "
                           "writes one)")


def world_spec(folder: Path, meta: dict, override: str | None) -> tuple[str, object]:
    """(spec text, world): `override` (`synthetic:NAME[?seed=N]`, the seed defaulting to the
    session's) when given, else the synthetic world the session's meta records."""
    from ibr.scene import parse_scene_spec
    from ibr.synthetic import make_world

    if override is None:
        if "world" not in meta:
            raise EvalCaptureError(f"{folder}: the session does not record the synthetic world it was captured in "
                                   "(no 'world' in session.json's meta); give --world synthetic:NAME?seed=N")
        if meta.get("robot", "sim") != "sim":
            raise EvalCaptureError(f"{folder}: photos of a real robot ({meta['robot']}), not of a synthetic world; "
                                   "give --world synthetic:NAME?seed=N to compare with one anyway")
        override = f"synthetic:{meta['world']}?seed={int(meta.get('seed', 0))}"
    spec = parse_scene_spec(override, synthetic_only=True, allowed=("seed",))
    seed = spec.seed(int(meta.get("seed", 0)))
    return f"synthetic:{spec.world}?seed={seed}", make_world(spec.world, seed)


def load_model(folder: Path):
    """The session's final model as a Scene (views posed by the model, its mesh); an error
    naming the folder when the mission wrote none (it did not finish)."""
    from ibr.capture import read_capture
    from ibr.scene import load_capture

    cap = read_capture(folder)
    if cap.model is None:
        raise EvalCaptureError(f"{folder}: the session has no final model (model/) yet: its mission did not finish "
                               f"(resume it with `ibrnav demo --session {folder}`)")
    scene = load_capture(folder)
    if scene.mesh is None or not len(scene):
        raise EvalCaptureError(f"{folder / 'model'}: the final model has no mesh.ply or no posed photo")
    return cap, scene


def true_cameras(cap, cameras: list) -> list:
    """`cameras` (named after their photo files) moved to the simulator's true pose of their
    photo: the `evaluation` record the mission logs after each photo of a simulated robot."""
    from robot.protocol import robot_camera

    truth, last = {}, None
    for r in cap.records:
        if r["kind"] == "photo":
            last = Path(r["file"]).stem
        elif r["kind"] == "evaluation" and last is not None and r.get("true_pose") is not None:
            truth[last] = r["true_pose"]
    missing = [c.name for c in cameras if c.name not in truth]
    if missing:
        raise EvalCaptureError(f"{cap.folder}: no true pose logged for {len(missing)} photos ({missing[0]}, ...); "
                               "--truth poses needs a simulated robot's session")
    return [robot_camera(truth[c.name], c.K, (c.width, c.height), cap.cam_from_robot, name=c.name) for c in cameras]


def _check_args(args: argparse.Namespace) -> None:
    if args.poses < 1:
        raise EvalCaptureError(f"--poses {args.poses}: must be >= 1")
    if not 0 < args.scale <= 1:
        raise EvalCaptureError(f"--scale {args.scale}: must be in (0, 1]")
    if args.json is not None and (Path(args.json).is_dir() or not Path(args.json).parent.is_dir()):
        raise EvalCaptureError(f"--json {args.json}: not a writable file path (folder missing or a folder given)")


def run(args: argparse.Namespace) -> int:
    from ibr.camera import Camera
    from ibr.progress import counter
    from ibr.render.ulr import UlrConfig
    from robot.mission import viz as mission_viz
    from robot.mission.evaluation import eval_capture

    t0 = time.perf_counter()
    _check_args(args)
    folder = session_folder(args.session)
    cap, scene = load_model(folder)
    spec, world = world_spec(folder, cap.meta, args.world)
    seed = int(cap.meta.get("seed", 0)) + 1 if args.seed is None else args.seed
    view = Camera(cap.intrinsics, *cap.image_size, np.eye(4)).scaled(args.scale)
    log.info(f"{folder}: {len(scene)} photos in the final model, {len(scene.mesh.faces)} faces; "
             f"ULR at {args.poses} poses of {spec} ({view.width}x{view.height} px)")
    cameras = true_cameras(cap, scene.cameras) if "poses" in args.truth else scene.cameras
    mesh = world.mesh if "mesh" in args.truth else scene.mesh
    recording.rerun_setup(args, "ibrnav_eval_capture", "ibrnav_eval_capture.rrd")
    _log_model(scene, cameras, mesh)
    views, bar = [], counter(args.poses, "views", log)

    def on_view(k, pose, cam, rendered, truth, metrics) -> None:
        views.append({"pose": [float(v) for v in pose], **metrics})
        mission_viz.log_eval_view(k, cam, rendered, truth, metrics)
        bar.update()

    result = eval_capture(world, cameras, [v.image for v in scene.views], mesh, args.poses,
                          np.random.default_rng(seed), view.K, (view.width, view.height), cap.cam_from_robot,
                          on_view=on_view, ulr_config=UlrConfig(blending=METHODS[args.method]))
    bar.close()
    recording.rerun_teardown(args)
    report = {"session": str(folder), "world": spec, "method": args.method, "truth": sorted(args.truth), "seed": seed,
              "photos": len(scene), "size": [view.width, view.height], **result, "views": views,
              "seconds": time.perf_counter() - t0}
    if args.json:
        jsonout.write(args.json, report, indent=1)
    print(_summary_line(report))
    return 0


def _log_model(scene, cameras: list, mesh) -> None:
    """What is rendered, in the recording: the model's points, the mesh and the photos'
    cameras (the model's, or the true ones with --truth)."""
    from robot.mission import viz as mission_viz

    if scene.points is not None:
        mission_viz.log_robot_map(scene.points, scene.point_colors, mesh)
    for cam in cameras:
        mission_viz.log_posed_photo(cam)


def _summary_line(r: dict) -> str:
    def f(d: dict, fmt: str) -> str:
        return "none" if d["mean"] is None else f"{d['mean']:{fmt}} (worst decile {d['worst_decile']:{fmt}})"

    how = r["method"] + "".join(f", true {t}" for t in r["truth"])
    return (f"{r['session']}: ULR of {r['photos']} photos ({how}) at {r['poses']} poses of {r['world']}: PSNR "
            f"{f(r['psnr_db'], '.2f')} dB, SSIM {f(r['ssim'], '.3f')}, covered {f(r['covered'], '.3f')} "
            f"({r['seconds']:.0f} s)")


def register(subparsers) -> None:
    p = subparsers.add_parser("eval-capture", help="ULR of a capture session's final model at random free-space "
                              "poses against the synthetic world's true renders (PSNR / SSIM / covered)")
    p.add_argument("session", help="a capture session folder with a final model (ibrnav demo --session DIR), "
                   "or its model/ folder")
    p.add_argument("--world", default=None, help="synthetic:NAME[?seed=N], the world the photos were taken in "
                   "(default: the one the session records; the seed defaults to the session's)")
    p.add_argument("--method", choices=tuple(METHODS), default="ulr", help="ulr: Buehler's sparse blending field "
                   "(as explore --json); ulr-pixel: per-pixel weights, the quality reference")
    p.add_argument("--poses", type=int, default=50, help="random free-space poses (camera height, random headings)")
    p.add_argument("--seed", type=int, default=None, help="seed of the poses (default: the session's seed + 1, the "
                   "poses explore --json draws at that --seed)")
    p.add_argument("--scale", type=float, default=0.5, help="render and compare at this fraction of the photos' "
                   "resolution (explore --json: 0.5)")
    p.add_argument("--truth", nargs="+", choices=("poses", "mesh"), default=[], help="replace the model's photo "
                   "poses by the simulator's true ones (logged in the session) and/or its mesh by the world's: the "
                   "quality the same photos give without the mission's localisation or proxy errors")
    p.add_argument("--json", default=None, help="write the report here")
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
