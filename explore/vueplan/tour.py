"""Tour of the Phase I viewpoints (Blaer & Allen 2009, Sec. 5.2.1): a travelling-salesperson
problem whose edge costs are the roadmap path lengths between viewpoints, solved with the
`fast-tsp` package (MIT): exactly up to 20 viewpoints, by its Or-opt / Lin-Kernighan local
search above. The tour is closed (it returns to its start).

Frame: world xy, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import fast_tsp
import numpy as np
from scipy.sparse.csgraph import shortest_path

from explore.vueplan.roadmap import Roadmap, RoadmapError, shortest_paths


@dataclass
class Tour:
    """order: viewpoint indices in visiting order (closed: back to order[0]); length_m:
    total path length (metres); path (K, 2): the concatenated roadmap polyline."""

    order: list[int]
    length_m: float
    path: np.ndarray


TSP_UNITS = 60000
"""Integer cost of the longest leg: fast-tsp takes costs that fit in 16 bits, so lengths are
scaled to this many units of the longest one (a relative resolution of 1.7e-5 of the
longest leg, whatever the site's size)."""
TSP_SECONDS = 1.0
"""fast-tsp's time budget for more than 20 viewpoints (fewer are solved exactly); it stops
earlier once its search has converged."""


def integer_costs(lengths: np.ndarray) -> np.ndarray:
    """The symmetric cost matrix (n, n) in integer units (`TSP_UNITS` for the longest leg),
    closed under the triangle inequality (rounding can break it by a unit, and fast-tsp's
    search relies on it): every cost is replaced by its shortest path over the others."""
    sym = (lengths + lengths.T) / 2
    cost = np.round(sym * (TSP_UNITS / max(float(sym.max()), 1e-12)))
    return np.round(shortest_path(cost, method="FW", directed=False)).astype(np.int64)


def solve_tsp(lengths: np.ndarray, seconds: float = TSP_SECONDS) -> list[int]:
    """A closed tour (visiting order starting at 0) through n points with the cost matrix
    lengths (n, n) (metres; symmetric, finite): exact up to 20 points, fast-tsp's local
    search within `seconds` above."""
    n = len(lengths)
    if n <= 3:
        return list(range(n))
    order = [int(i) for i in fast_tsp.find_tour(integer_costs(lengths).tolist(), duration_seconds=seconds,
                                                  stop_when_converged=True)]
    k = order.index(0)
    return order[k:] + order[:k]


def plan_tour(roadmap: Roadmap, viewpoints: np.ndarray, seconds: float = TSP_SECONDS) -> Tour:
    """The shortest closed tour of viewpoints (n, 2) along roadmap paths."""
    lengths, paths = shortest_paths(roadmap, viewpoints)
    if not np.isfinite(lengths).all():
        bad = sorted({int(i) for i in np.argwhere(~np.isfinite(lengths))[:, 1]})
        raise RoadmapError(f"viewpoints {bad} cannot be reached over the roadmap from the others "
                           "(the free space is in unconnected parts)")
    order = solve_tsp(lengths, seconds)
    legs = [paths[a][b] for a, b in zip(order, order[1:] + order[:1])] if len(order) > 1 else []
    path = np.vstack([legs[0]] + [leg[1:] for leg in legs[1:]]) if legs else viewpoints[order]
    total = float(sum(lengths[a, b] for a, b in zip(order, order[1:] + order[:1]))) if len(order) > 1 else 0.0
    return Tour(order, total, path)
