"""`ibrnav vueplan SITE`: VuePlan's two-phase view planning on a site (Blaer & Allen 2009):
Phase I views from the 2-D map, the roadmap tour of them, simulated scans, then Phase II
next-best views on the voxel space, from the potential views the robot can reach, until the
best one sees fewer boundary-unseen voxels than --stop-fraction of them (the unseen boundary
in sight is exhausted). Prints the paper's per-iteration table and how much of the true
surface any reachable view has in sight (the most Phase II could cover); progress goes to
stderr.

SITE: `synthetic:NAME[?seed=N]` (the world's mesh and free space), or a mesh file with
`--floorplan FILE.geojson|.wkt` (or, without it, a slice of the mesh at --slice-height).
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from ibr.errors import InputError
from ibrnav import jsonout, recording

RAY_BACKENDS = ("gl", "embree", "walk")  # explore.vueplan.phase2.RAY_BACKENDS (imported lazily there)

log = logging.getLogger(__name__)


def print_table(rows: list, in_sight: float | None = None) -> None:
    print(f"{'At the end of':<14}{'Seen-occupied':>14}{'Total unseen':>14}{'Boundary unseen':>17}"
          f"{'Visible to NBV':>16}{'Surface cov.':>14}{'NBV s':>8}")
    for k, r in enumerate(rows):
        print(f"{'Phase I' if k == 0 else f'NBV {k}':<14}{r.seen_occupied:>14,}{r.unseen:>14,}"
              f"{r.boundary_unseen:>17,}{r.visible_to_nbv:>16,}{r.surface_coverage:>14.3f}{r.seconds:>8.2f}")
    if rows:
        print(f"stopped: {rows[-1].stop}")
    if in_sight is not None and rows:
        final = rows[-1].surface_coverage
        print(f"true surface in sight of some reachable view: {in_sight:.3f}; covered: {final:.3f} "
              f"({final / max(in_sight, 1e-12):.3f} of what is in sight)")


def check_flags(args: argparse.Namespace) -> None:
    """One clear error for flag values the planners cannot use."""
    for flag in ("candidates", "voxel", "scan_resolution", "max_range", "candidate_stride",
                 "surface_samples", "roadmap_spacing", "max_nbv"):
        if getattr(args, flag) <= 0:
            raise InputError(f"--{flag.replace('_', '-')} must be positive, got {getattr(args, flag)}")
    if not 0 <= args.min_range < args.max_range:
        raise InputError(f"--min-range {args.min_range} must be in [0, --max-range {args.max_range})")
    if not 0 <= args.stop_fraction < 1:
        raise InputError(f"--stop-fraction {args.stop_fraction} must be in [0, 1)")
    if not 0 < args.fov <= 360 or not 0 < args.grazing < 90:
        raise InputError(f"--fov {args.fov} must be in (0, 360] and --grazing {args.grazing} "
                         "in (0, 90) degrees")


def run(args: argparse.Namespace) -> int:
    from explore.vueplan import viz as vv
    from explore.vueplan.phase1 import Phase1Config, plan_phase1
    from explore.vueplan.roadmap import build_roadmap
    from explore.vueplan.site import load_site
    from explore.vueplan.tour import plan_tour
    from ibr import viz

    check_flags(args)
    rng = np.random.default_rng(args.seed)
    mesh, plan, renderer, height = load_site(args.site, args.floorplan, args.cover_outer, args.slice_height,
                                             args.scan_height)
    recording.rerun_setup(args, "ibrnav_vueplan", "vueplan.rrd")
    viz.log_mesh("world/map/mesh", mesh)
    out: dict = {}

    p1cfg = Phase1Config(n_candidates=args.candidates, min_range_m=args.min_range,
                         max_range_m=args.max_range, max_grazing_rad=np.deg2rad(args.grazing),
                         field_of_view_rad=np.deg2rad(args.fov), min_overlap=args.overlap,
                         min_gain=args.min_gain, coverage_target=args.coverage_target)
    log.info(f"Phase I: {args.candidates} candidates")
    p1 = plan_phase1(plan, p1cfg, rng)
    if not p1.chosen:
        raise InputError(f"{args.site}: Phase I found no view that sees any wall")
    log.info(f"Phase I: {len(p1.chosen)} views, {100 * p1.boundary_coverage:.1f}% of the wall "
              f"boundary in {p1.seconds:.2f} s")
    out["phase1"] = {"views": len(p1.chosen), "boundary_coverage": p1.boundary_coverage,
                     "seconds": p1.seconds}
    vv.log_phase1(p1.positions, p1.chosen, plan.wall_segments())

    roadmap = build_roadmap(plan, args.roadmap_spacing)
    tour = plan_tour(roadmap, p1.views)
    log.info(f"tour: {tour.length_m:.1f} m over a {len(roadmap.nodes)}-node Voronoi roadmap")
    vv.log_roadmap(roadmap.nodes, roadmap.edges)
    vv.log_tour(tour.path)

    out["phase2"] = []
    if not args.phase1_only:
        out["phase2"], out["surface_in_sight"] = run_phase2(args, mesh, plan, renderer, height,
                                                            p1.views[tour.order], rng, vv)
    out["tour_length_m"] = tour.length_m
    if args.json:
        jsonout.write(args.json, out)
    recording.rerun_teardown(args)
    return 0


def run_phase2(args, mesh, plan, renderer, height, views_xy, rng, vv) -> tuple[list[dict], float]:
    """Phase II from the Phase I scans; returns the table's rows and the fraction of the true
    surface in sight of some reachable potential view."""
    from explore.vueplan.phase2 import (Phase2Config, SurfaceCoverage, ground_candidates, plan_phase2,
                                        reachable_views)
    from explore.vueplan.scan_simulator import ScanConfig, simulate_scan
    from explore.vueplan.voxel_grid import VoxelGrid, insert_scan
    from ibr.progress import counter, progress

    scfg = ScanConfig(resolution_deg=args.scan_resolution, min_range_m=args.min_range,
                      max_range_m=args.max_range, range_noise_m=args.range_noise)
    lo, hi = mesh.bounds
    grid = VoxelGrid.covering([lo[0], lo[1], 0.0], [hi[0], hi[1], hi[2] + args.voxel], args.voxel)
    coverage = SurfaceCoverage(mesh, args.surface_samples, rng, tol_m=max(0.1, args.voxel / 2))
    step = 0

    def acquire(origin: np.ndarray):
        nonlocal step
        t = time.perf_counter()
        scan = simulate_scan(renderer, origin, scfg, rng)
        coverage.add(scan.points)
        vv.log_scan(step, f"scan_{step:02d}", origin, scan.points)
        log.info(f"scan {step} at ({origin[0]:.1f}, {origin[1]:.1f}): {len(scan.points)} points "
                  f"in {time.perf_counter() - t:.1f} s")
        step += 1
        return scan

    log.info(f"voxel grid {grid.shape} ({np.prod(grid.shape):,} voxels of {args.voxel} m)")
    for xy in progress(views_xy, desc="Phase I scans", logger=log):
        scan = acquire(np.r_[xy, height])
        insert_scan(grid, scan.origin, scan.points, scan.no_return, scan.max_range_m)
    p2cfg = Phase2Config(min_range_m=args.min_range, max_range_m=args.max_range,
                         max_grazing_rad=np.deg2rad(args.grazing), stop_fraction=args.stop_fraction,
                         max_views=args.max_nbv, sensor_height_m=height,
                         candidate_stride=args.candidate_stride, ray_backend=args.ray_backend)
    candidates = ground_candidates(grid, plan.free_space, p2cfg)
    candidates = candidates[reachable_views(candidates, plan.free_space, views_xy, p2cfg.candidate_clearance_m)]
    log.info(f"Phase II: {len(candidates)} reachable potential views, stop below "
             f"{args.stop_fraction:.3f} of the boundary unseen")

    def on_row(row, counts):
        k = len(rows_seen)
        rows_seen.append(row)
        bar.update()
        vv.log_voxels(step, grid)
        vv.log_nbv_candidates(step, candidates, counts, row.nbv)
        vv.log_phase2_row(step, row)
        log.info(f"{'Phase I' if k == 0 else f'NBV {k}'}: boundary unseen {row.boundary_unseen}, "
                  f"best view sees {row.visible_to_nbv} ({row.seconds:.1f} s)")

    rows_seen: list = []
    bar = counter(args.max_nbv + 1, "NBV iterations", log)
    rows = plan_phase2(grid, candidates, acquire, p2cfg, lambda: coverage.fraction, on_row)
    bar.close()
    t = time.perf_counter()
    poses = np.vstack([candidates, np.c_[views_xy, np.full(len(views_xy), height)]])  # + the Phase I scans
    in_sight = float(coverage.in_sight(mesh, poses, args.min_range, args.max_range).mean())
    log.info(f"true surface in sight of some reachable view: {in_sight:.3f} ({time.perf_counter() - t:.1f} s)")
    print_table(rows, in_sight)
    return [r.as_json() for r in rows], in_sight


def register(subparsers) -> None:
    p = subparsers.add_parser("vueplan", help="VuePlan two-phase view planning on a site (Blaer & Allen)")
    p.add_argument("site", help="synthetic:NAME[?seed=N] or a mesh file (with --floorplan or a slice)")
    p.add_argument("--floorplan", help="free-space floor plan (.geojson / .wkt) for a mesh site")
    p.add_argument("--slice-height", type=float, default=0.5, help="mesh slice height without --floorplan (m)")
    p.add_argument("--scan-height", type=float, default=1.6, help="scanner height for a mesh site (m)")
    p.add_argument("--cover-outer", action="store_true",
                   help="the floor plan's exterior ring is a wall to cover")
    p.add_argument("--phase1-only", action="store_true", help="plan Phase I views and the tour only")
    p.add_argument("--candidates", type=int, default=500, help="Phase I random candidates")
    p.add_argument("--min-range", type=float, default=0.5, help="scanner minimum range (m)")
    p.add_argument("--max-range", type=float, default=30.0, help="scanner maximum range (m)")
    p.add_argument("--grazing", type=float, default=70.0, help="maximum grazing angle (deg)")
    p.add_argument("--fov", type=float, default=360.0, help="Phase I horizontal field of view (deg)")
    p.add_argument("--overlap", type=float, default=0.1, help="Phase I overlap constraint (fraction)")
    p.add_argument("--min-gain", type=float, default=0.02, help="Phase I stop: gain below this fraction")
    p.add_argument("--coverage-target", type=float, default=1.0,
                   help="Phase I stop: coverage fraction")
    p.add_argument("--roadmap-spacing", type=float, default=0.5,
                   help="obstacle edge sampling for the Voronoi roadmap (m)")
    p.add_argument("--voxel", type=float, default=0.5, help="Phase II voxel size (m)")
    p.add_argument("--candidate-stride", type=int, default=2,
                   help="Phase II: every n-th ground voxel is a potential view")
    p.add_argument("--stop-fraction", type=float, default=0.02,
                   help="Phase II stop: the best view sees fewer than this fraction of the boundary-unseen voxels")
    p.add_argument("--ray-backend", choices=RAY_BACKENDS, default="gl",
                   help="Phase II visibility test: GL compute pass (default), Embree ray queries (exact "
                        "reference) or the numpy voxel walk")
    p.add_argument("--max-nbv", type=int, default=30, help="Phase II: at most this many next-best views (a guard)")
    p.add_argument("--scan-resolution", type=float, default=0.5,
                   help="simulated scanner beam step (deg)")
    p.add_argument("--range-noise", type=float, default=0.0, help="simulated range noise sigma (m)")
    p.add_argument("--surface-samples", type=int, default=20000,
                   help="true-surface samples for coverage")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.add_argument("--json", help="write the results to this JSON file")
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
