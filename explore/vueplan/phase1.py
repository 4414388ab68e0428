"""VuePlan Phase I: 2-D view planning with sensor constraints (Blaer & Allen, "View
Planning and Automated Data Acquisition for Three-Dimensional Modeling of Complex Sites",
J. Field Robotics 2009, Sec. 3.1, Algorithm 1).

    procedure 2DPLAN(M)
      randomly distribute candidate views V in the map          -> sample_candidates
      for all views v in V:
        compute the visibility polygon p of v                   -> visible_obstacle_edges
        clip p to sensor range                                  -> clip_to_range
        clip p to maximum grazing angle                         -> clip_to_grazing_angle
        clip p to field of view                                 -> clip_to_field_of_view
      find a greedy cover G from V that enforces the overlap    -> greedy_cover
      constraint; return G

The visibility polygon comes from the paper's angular ray sweep (`explore.visibility`; it
agrees with CGAL's exact triangular expansion to 1e-13 of the area). Only its edges that
lie on the free-space boundary ("obstacle edges") are kept; the edges in the interior of
the free space are dropped. All clipping runs vectorised over the edges of every
candidate at once. Segments are (M, 2, 2) arrays of end points in metres (world xy).

For the set cover the wall boundary is cut into short elements (`element_m`); a view
covers an element when the element's midpoint lies on one of its clipped edges. The
greedy cover picks, among views whose already-seen share of what they see is at least
`min_overlap` (the overlap constraint, waived for the first view), the one that adds the
most new wall length; it stops when the best view adds less than `min_gain` of the total
wall length or coverage reaches `coverage_target`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import shapely

from explore.floorplan import FloorPlan, FloorPlanError
from explore.visibility import VisibilityPolygons


@dataclass(frozen=True)
class Phase1Config:
    """Sensor and planner settings of Phase I."""

    n_candidates: int = 500
    """Number of random candidate views N."""
    min_range_m: float = 0.5
    """Scanner minimum range (metres): wall parts closer than this are not imaged."""
    max_range_m: float = 30.0
    """Scanner maximum range (metres)."""
    max_grazing_rad: float = np.deg2rad(70.0)
    """Largest angle between the line of sight and a wall's normal that still images it."""
    field_of_view_rad: float = 2 * np.pi
    """Horizontal field of view; below 2 pi every candidate also gets a random heading."""
    min_overlap: float = 0.1
    """Overlap constraint: share of a new view's visible wall length already seen."""
    min_gain: float = 0.02
    """Stop when the best view adds less than this fraction of the total wall length."""
    coverage_target: float = 1.0
    """Stop when this fraction of the wall length is covered."""
    element_m: float = 0.1
    """Length of the wall elements the set cover counts (metres)."""
    clearance_m: float = 0.3
    """Candidates stand at least this far from the free-space boundary (metres)."""


@dataclass
class Phase1Result:
    """positions (N, 2) metres and headings (N,) rad of all candidates; cover (N, Q) bool,
    which wall elements each candidate images; element_length (Q,) metres; chosen: indices
    of the planned views in greedy order; coverage: covered wall fraction after each
    chosen view; seconds: planning time."""

    positions: np.ndarray
    headings: np.ndarray
    cover: np.ndarray
    element_length: np.ndarray
    chosen: list[int]
    coverage: list[float]
    seconds: float = 0.0

    @property
    def views(self) -> np.ndarray:
        """(G, 2) planned view positions, metres."""
        return self.positions[self.chosen]

    @property
    def view_headings(self) -> np.ndarray:
        return self.headings[self.chosen]

    @property
    def boundary_coverage(self) -> float:
        return self.coverage[-1] if self.coverage else 0.0


# ---------------------------------------------------------------- candidates

def sample_candidates(free_space: shapely.Geometry, n: int, rng: np.random.Generator,
                      clearance_m: float = 0.3, field_of_view_rad: float = 2 * np.pi
                      ) -> tuple[np.ndarray, np.ndarray]:
    """n uniform random positions (n, 2) in `free_space` at least clearance_m from its
    boundary, and headings (n,) in [-pi, pi) (all 0 when the field of view is 360 deg)."""
    region = free_space.buffer(-clearance_m) if clearance_m > 0 else free_space
    if region.is_empty:
        raise FloorPlanError(f"the floor plan has no free space {clearance_m} m away from its "
                             "boundary to place candidate views in")
    x0, y0, x1, y1 = region.bounds
    out = np.empty((0, 2))
    while len(out) < n:
        m = max(64, 2 * (n - len(out)) * int(np.ceil((x1 - x0) * (y1 - y0) / region.area)))
        p = rng.uniform((x0, y0), (x1, y1), (m, 2))
        out = np.concatenate([out, p[shapely.contains_xy(region, p[:, 0], p[:, 1])]])
    headings = (rng.uniform(-np.pi, np.pi, n) if field_of_view_rad < 2 * np.pi
                else np.zeros(n))
    return out[:n], headings


# ---------------------------------------------------------------- visibility polygon

def obstacle_edges(polygon: np.ndarray, boundary: np.ndarray, tol: float = 1e-6
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The edges of a visibility polygon (K, 2) that lie on the free-space boundary
    (E, 2, 2): segments (M, 2, 2) and the boundary edge index (M,) each lies on. The other
    edges (inside the free space) are dropped."""
    if len(polygon) < 3:
        return np.empty((0, 2, 2)), np.empty(0, int)
    edges = np.stack([polygon, np.roll(polygon, -1, axis=0)], axis=1)
    d = np.maximum(_point_segment_distance(edges[:, 0], boundary),
                   _point_segment_distance(edges[:, 1], boundary))  # (K, E)
    owner = d.argmin(axis=1)
    scale = tol * max(1.0, np.abs(boundary).max())
    keep = (d[np.arange(len(edges)), owner] <= scale) & (
        np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1) > scale)
    return edges[keep], owner[keep]


def _point_segment_distance(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """(K, E) distances from points p (K, 2) to segments (E, 2, 2)."""
    a, d = segs[None, :, 0], (segs[:, 1] - segs[:, 0])[None]
    t = np.clip(np.einsum("ked,ked->ke", p[:, None] - a, d) / np.maximum(
        np.einsum("ked,ked->ke", d, d), 1e-300), 0, 1)
    return np.linalg.norm(a + t[..., None] * d - p[:, None], axis=-1)


def visible_obstacle_edges(vis: VisibilityPolygons, positions: np.ndarray, boundary: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Obstacle edges seen from every position (N, 2): segments (M, 2, 2), the candidate
    (M,) and the boundary edge (M,) each belongs to."""
    segs, cand, owner = [], [], []
    for i, xy in enumerate(positions):
        s, o = obstacle_edges(vis(xy), boundary)
        segs.append(s)
        owner.append(o)
        cand.append(np.full(len(s), i))
    return np.concatenate(segs), np.concatenate(cand), np.concatenate(owner)


# ---------------------------------------------------------------- sensor constraints

def _pieces(segs: np.ndarray, t0: np.ndarray, t1: np.ndarray, eps: float = 1e-12
            ) -> tuple[np.ndarray, np.ndarray]:
    """Sub-segments segs[i] between parameters t0[i] < t1[i] (t in [0, 1]); returns the
    non-empty ones (K, 2, 2) and their parent indices (K,)."""
    keep = t1 - t0 > eps
    p0, d = segs[keep, 0], segs[keep, 1] - segs[keep, 0]
    out = np.stack([p0 + t0[keep, None] * d, p0 + t1[keep, None] * d], axis=1)
    return out, np.flatnonzero(keep)


def _circle_params(segs: np.ndarray, center: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Parameters t1 <= t2 where each segment's line meets the circle (center (M, 2),
    radius r); NaN where the line misses it."""
    d = segs[:, 1] - segs[:, 0]
    f = segs[:, 0] - center
    a = np.einsum("md,md->m", d, d)
    b = 2 * np.einsum("md,md->m", f, d)
    c = np.einsum("md,md->m", f, f) - r * r
    disc = b * b - 4 * a * c
    root = np.sqrt(np.where(disc > 0, disc, np.nan))
    return (-b - root) / (2 * a), (-b + root) / (2 * a)


def clip_to_range(segs: np.ndarray, center: np.ndarray, min_range: float, max_range: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Keep the parts of segments (M, 2, 2) between min_range and max_range (metres) of
    their view center (M, 2) (paper Sec. 3.1.1): inside the max-range circle, a segment
    is kept whole (both ends inside), cut at the circle (one end inside), or cut to the
    chord (both outside and the line crosses the circle) or dropped; the parts inside the
    min-range circle are dropped, which can split a segment in two. Returns the pieces
    (K, 2, 2) and their parent indices (K,)."""
    t1, t2 = _circle_params(segs, center, max_range)
    lo = np.clip(np.nan_to_num(t1, nan=1.0), 0, 1)
    hi = np.clip(np.nan_to_num(t2, nan=0.0), 0, 1)
    if min_range <= 0:
        return _pieces(segs, lo, hi)
    s1, s2 = _circle_params(segs, center, min_range)
    s1, s2 = np.nan_to_num(s1, nan=2.0), np.nan_to_num(s2, nan=2.0)  # no cut when missed
    a, ia = _pieces(segs, lo, np.minimum(hi, s1))
    b, ib = _pieces(segs, np.maximum(lo, s2), hi)
    order = np.argsort(np.r_[ia, ib], kind="stable")
    return np.concatenate([a, b])[order], np.r_[ia, ib][order]


def clip_to_grazing_angle(segs: np.ndarray, center: np.ndarray, max_grazing: float
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Keep the sub-segment on which the angle between the line of sight from the view
    center (M, 2) and the segment's normal is at most max_grazing (rad) (paper Fig. 2):
    with D the distance from the center to the segment's line and s the position along
    the line from the foot of the perpendicular, tan(theta) = |s| / D, so the kept part
    is |s| <= D tan(max_grazing). Returns pieces (K, 2, 2) and parent indices (K,)."""
    d = segs[:, 1] - segs[:, 0]
    L = np.linalg.norm(d, axis=1)
    u = d / L[:, None]
    w = center - segs[:, 0]
    s_foot = np.einsum("md,md->m", w, u)
    D = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
    half = D * np.tan(min(max_grazing, np.pi / 2 - 1e-9))
    return _pieces(segs, np.clip((s_foot - half) / L, 0, 1), np.clip((s_foot + half) / L, 0, 1))


def clip_to_field_of_view(segs: np.ndarray, center: np.ndarray, heading: np.ndarray,
                          field_of_view: float) -> tuple[np.ndarray, np.ndarray]:
    """Keep the parts of segments inside the horizontal field of view (rad) centred on
    each view's heading (M,) (rad, from the +x axis): the two bounding rays cut a segment
    into at most three pieces and a piece is kept when its midpoint's bearing is within
    half the field of view. Returns pieces (K, 2, 2) and parent indices (K,)."""
    if field_of_view >= 2 * np.pi:
        return segs.copy(), np.arange(len(segs))
    half = field_of_view / 2
    p0, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    cuts = [np.zeros(len(segs)), np.ones(len(segs))]
    for side in (-1.0, 1.0):
        a = heading + side * half
        r = np.c_[np.cos(a), np.sin(a)]
        # center + s r = p0 + t d  ->  solve for (s, t)
        den = r[:, 0] * -d[:, 1] - r[:, 1] * -d[:, 0]
        w = p0 - center
        ok = np.abs(den) > 1e-12
        den = np.where(ok, den, 1.0)
        s = (w[:, 0] * -d[:, 1] - w[:, 1] * -d[:, 0]) / den
        t = (r[:, 0] * w[:, 1] - r[:, 1] * w[:, 0]) / den
        cuts.append(np.where(ok & (s > 0) & (t > 0) & (t < 1), t, 1.0))
    ts = np.sort(np.stack(cuts, axis=1), axis=1)  # (M, 4)
    pieces, parents = [], []
    for k in range(3):
        mid = p0 + 0.5 * (ts[:, k] + ts[:, k + 1])[:, None] * d
        bearing = np.arctan2(mid[:, 1] - center[:, 1], mid[:, 0] - center[:, 0])
        inside = np.abs(np.angle(np.exp(1j * (bearing - heading)))) <= half
        seg, par = _pieces(segs, ts[:, k], np.where(inside, ts[:, k + 1], ts[:, k]))
        pieces.append(seg)
        parents.append(par)
    order = np.argsort(np.concatenate(parents), kind="stable")
    return np.concatenate(pieces)[order], np.concatenate(parents)[order]


def clip_to_sensor(segs: np.ndarray, center: np.ndarray, heading: np.ndarray,
                   cfg: Phase1Config) -> tuple[np.ndarray, np.ndarray]:
    """Range, then grazing angle, then field of view (Algorithm 1, lines 5-7). Returns
    pieces (K, 2, 2) and parent indices (K,) into segs."""
    idx = np.arange(len(segs))
    s, i = clip_to_range(segs, center, cfg.min_range_m, cfg.max_range_m)
    idx = idx[i]
    s, i = clip_to_grazing_angle(s, center[idx], cfg.max_grazing_rad)
    idx = idx[i]
    s, i = clip_to_field_of_view(s, center[idx], heading[idx], cfg.field_of_view_rad)
    return s, idx[i]


# ---------------------------------------------------------------- greedy cover

def wall_elements(walls: np.ndarray, element_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut wall segments (W, 2, 2) into pieces of about element_m: the wall index (Q,),
    midpoint parameter along the wall (Q,) and length (Q,) of every element, sorted by
    wall then parameter."""
    L = np.linalg.norm(walls[:, 1] - walls[:, 0], axis=1)
    n = np.maximum(1, np.ceil(L / element_m).astype(int))
    wall = np.repeat(np.arange(len(walls)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    return wall, (k + 0.5) / n[wall], (L / n)[wall]


def cover_matrix(segs: np.ndarray, cand: np.ndarray, wall: np.ndarray, walls: np.ndarray,
                 n_candidates: int, element_wall: np.ndarray, element_t: np.ndarray) -> np.ndarray:
    """(N, Q) bool: candidate i covers element q when q's midpoint lies on one of the
    clipped segments (M, 2, 2) of i on the element's wall (segment -> candidate cand,
    wall index `wall`)."""
    a, d = walls[wall, 0], walls[wall, 1] - walls[wall, 0]
    dd = np.einsum("md,md->m", d, d)
    t = np.stack([np.einsum("md,md->m", segs[:, j] - a, d) / dd for j in (0, 1)], axis=1)
    t0, t1 = t.min(axis=1), t.max(axis=1)
    key = element_wall + element_t * (1 - 1e-9)  # sorted
    lo = np.searchsorted(key, wall + t0 * (1 - 1e-9), side="left")
    hi = np.searchsorted(key, wall + t1 * (1 - 1e-9), side="right")
    diff = np.zeros((n_candidates, len(key) + 1), np.int32)
    np.add.at(diff, (cand, lo), 1)
    np.add.at(diff, (cand, hi), -1)
    return np.cumsum(diff[:, :-1], axis=1) > 0


def greedy_cover(cover: np.ndarray, length: np.ndarray, min_overlap: float, min_gain: float,
                 coverage_target: float) -> tuple[list[int], list[float]]:
    """Greedy set cover by wall length with the overlap constraint (Sec. 3.1.1). cover
    (N, Q) bool, length (Q,) metres. Returns the chosen indices and the covered fraction
    after each."""
    total = float(length.sum())
    seen = np.zeros(cover.shape[1], bool)
    visible = cover.astype(np.float64) @ length
    chosen, coverage = [], []
    while True:
        gain = cover[:, ~seen].astype(np.float64) @ length[~seen]
        overlap = cover[:, seen].astype(np.float64) @ length[seen]
        feasible = (overlap >= min_overlap * visible) if chosen else np.ones(len(cover), bool)
        gain = np.where(feasible, gain, -1.0)
        best = int(np.argmax(gain))
        if gain[best] < max(min_gain * total, 1e-12):
            break
        chosen.append(best)
        seen |= cover[best]
        coverage.append(float(length[seen].sum() / total))
        if coverage[-1] >= coverage_target:
            break
    return chosen, coverage


# ---------------------------------------------------------------- Algorithm 1

def plan_phase1(plan: FloorPlan, cfg: Phase1Config, rng: np.random.Generator,
                positions: np.ndarray | None = None, headings: np.ndarray | None = None
                ) -> Phase1Result:
    """Algorithm 1 (2DPLAN) on a floor plan: random candidates (or the given positions
    (N, 2) and headings (N,)), their clipped visible walls, the greedy cover."""
    t = time.perf_counter()
    if positions is None:
        positions, headings = sample_candidates(plan.free_space, cfg.n_candidates, rng,
                                                cfg.clearance_m, cfg.field_of_view_rad)
    headings = np.zeros(len(positions)) if headings is None else np.asarray(headings, float)
    boundary, is_wall = plan.boundary_segments()
    walls = boundary[is_wall]
    wall_of_boundary = np.cumsum(is_wall) - 1
    segs, cand, owner = visible_obstacle_edges(VisibilityPolygons(plan.free_space), positions, boundary)
    on_wall = is_wall[owner]
    segs, cand, owner = segs[on_wall], cand[on_wall], owner[on_wall]
    clipped, parent = clip_to_sensor(segs, positions[cand], headings[cand], cfg)
    ew, et, el = wall_elements(walls, cfg.element_m)
    cover = cover_matrix(clipped, cand[parent], wall_of_boundary[owner[parent]], walls,
                         len(positions), ew, et)
    chosen, coverage = greedy_cover(cover, el, cfg.min_overlap, cfg.min_gain, cfg.coverage_target)
    return Phase1Result(positions, headings, cover, el, chosen, coverage,
                        time.perf_counter() - t)
