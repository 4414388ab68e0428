"""Tour of the Phase I viewpoints (Blaer & Allen 2009, Sec. 5.2.1): a travelling-salesperson
problem whose edge costs are the roadmap path lengths between viewpoints, solved with
LKH through the `elkai` package. The tour is closed (it returns to its start).

Frame: world xy, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import elkai
import numpy as np

from explore.vueplan.roadmap import Roadmap, RoadmapError, shortest_paths


@dataclass
class Tour:
    """order: viewpoint indices in visiting order (closed: back to order[0]); length_m:
    total path length (metres); path (K, 2): the concatenated roadmap polyline."""

    order: list[int]
    length_m: float
    path: np.ndarray


def solve_tsp(lengths: np.ndarray, runs: int = 10) -> list[int]:
    """A closed tour (visiting order starting at 0) through n points with the cost matrix
    lengths (n, n) (metres; symmetric, finite), solved to the millimetre by LKH."""
    n = len(lengths)
    if n <= 3:
        return list(range(n))
    # LKH works on integers (elkai rounds float costs): use millimetres
    cost = np.round((lengths + lengths.T) / 2 * 1000.0).astype(np.int64)
    order = elkai.DistanceMatrix(cost.tolist()).solve_tsp(runs=runs)
    order = [int(i) for i in order]
    if len(order) == n + 1:  # elkai repeats the start at the end
        order = order[:-1]
    k = order.index(0)
    return order[k:] + order[:k]


def plan_tour(roadmap: Roadmap, viewpoints: np.ndarray, runs: int = 10) -> Tour:
    """The shortest closed tour of viewpoints (n, 2) along roadmap paths."""
    lengths, paths = shortest_paths(roadmap, viewpoints)
    if not np.isfinite(lengths).all():
        bad = sorted({int(i) for i in np.argwhere(~np.isfinite(lengths))[:, 1]})
        raise RoadmapError(f"viewpoints {bad} cannot be reached over the roadmap from the others "
                           "(the free space is in unconnected parts)")
    order = solve_tsp(lengths, runs)
    legs = [paths[a][b] for a, b in zip(order, order[1:] + order[:1])] if len(order) > 1 else []
    path = np.vstack([legs[0]] + [leg[1:] for leg in legs[1:]]) if legs else viewpoints[order]
    total = float(sum(lengths[a, b] for a, b in zip(order, order[1:] + order[:1]))) if len(order) > 1 else 0.0
    return Tour(order, total, path)
