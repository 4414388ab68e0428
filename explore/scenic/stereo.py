"""Stereo-pair cost of the Scenic Route Planner (Mendez et al., Sec. 3.3.2): how far a pair
of views (Left, Right) is from an "ideal" stereo pair, for successive poses on a path (SfM)
or for two agents (collaborative stereo). All functions are vectorised over N pairs.

I is the intersection of the principal rays r_L, r_R (the midpoint of their closest
points, on the rays); d_LI, d_RI the distances from the cameras to I and d_B the baseline.
The ideal pair has d_LI = d_RI = α d_B (5), which fixes the vergence angle
β* = acos(1 - 1 / (2 α²)).

    C_B = |d_LI - α d_B| / (α d_B) + |d_RI - α d_B| / (α d_B) + |d_LI - d_RI| / d_B   (6)
    C_T = acos(|r_L · r_LI| / (‖r_L‖‖r_LI‖)) + acos(|r_R · r_RI| / (‖r_R‖‖r_RI‖))       (7)
    C_G = acos(|r_LI · r_LG| / (‖r_LI‖‖r_LG‖)) + acos(|r_RI · r_RG| / (‖r_RI‖‖r_RG‖))   (8)
    C(L, R) = σ1 C_B + σ2 C_β + σ3 C_T + C_G                                            (9)

G is the occupied voxel (Vo) nearest to I. The paper names C_β without writing it out;
here C_β = |β - β*| with β the angle at I between the rays back to the two cameras.
Units: metres, radians; costs are dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class StereoCostConfig:
    alpha: float = 3.0
    """Distance to the vergence point in baselines, d_LI = d_RI = α d_B (paper: 3)."""
    sigma_b: float = 1.0
    """Weight σ1 of the baseline cost C_B."""
    sigma_beta: float = 1.0
    """Weight σ2 of the vergence-angle cost C_β."""
    sigma_t: float = 1.0
    """Weight σ3 of the principal-ray cost C_T."""
    far_m: float = 50.0
    """Where I is put along (almost) parallel principal rays (metres)."""


def ray_intersection(L, R, r_l, r_r, far_m: float = 50.0) -> np.ndarray:
    """(N, 3) midpoint of the closest points of the rays L + s r_L and R + t r_R (s, t >= 0);
    r_* unit (N, 3)."""
    w0 = L - R
    b = np.sum(r_l * r_r, -1)
    d = np.sum(r_l * w0, -1)
    e = np.sum(r_r * w0, -1)
    den = 1.0 - b ** 2
    par = den < 1e-9
    s = np.where(par, far_m, (b * e - d) / np.where(par, 1.0, den))
    t = np.where(par, far_m, (e - b * d) / np.where(par, 1.0, den))
    s, t = np.clip(s, 0.0, far_m), np.clip(t, 0.0, far_m)
    return 0.5 * (L + s[:, None] * r_l + R + t[:, None] * r_r)


def _angle(a: np.ndarray, b: np.ndarray, absolute: bool = True) -> np.ndarray:
    """Angle (radians) between rows of a and b; with `absolute`, of |a·b| as in (7), (8)."""
    c = np.sum(a * b, -1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
    return np.arccos(np.clip(np.abs(c) if absolute else c, -1.0, 1.0))


def baseline_cost(d_li, d_ri, d_b, alpha: float) -> np.ndarray:
    """C_B, eq. (6); baselines under 1 cm count as 1 cm (a pair of one pose is bad, not infinite)."""
    d_b = np.maximum(d_b, 0.01)
    return (np.abs(d_li - alpha * d_b) + np.abs(d_ri - alpha * d_b)) / (alpha * d_b) + np.abs(d_li - d_ri) / d_b


def vergence_cost(L, R, I, alpha: float) -> np.ndarray:
    """C_β = |β - β*|: vergence angle at I against β* = acos(1 - 1/(2α²)) (radians)."""
    beta_ideal = np.arccos(1.0 - 1.0 / (2.0 * alpha ** 2))
    return np.abs(_angle(L - I, R - I, absolute=False) - beta_ideal)


def stereo_terms(L, R, r_l, r_r, occupied: cKDTree | None,
                 config: StereoCostConfig = StereoCostConfig()) -> dict[str, np.ndarray]:
    """C_B, C_β, C_T, C_G (each (N,)) of pairs with centres L, R (N, 3) and unit principal
    rays r_l, r_r (N, 3); `occupied` a KD-tree of occupied voxel centres (None: C_G = 0)."""
    L, R, r_l, r_r = (np.atleast_2d(np.asarray(x, float)) for x in (L, R, r_l, r_r))
    I = ray_intersection(L, R, r_l, r_r, config.far_m)
    r_li, r_ri = I - L, I - R
    d_li, d_ri = np.linalg.norm(r_li, axis=1), np.linalg.norm(r_ri, axis=1)
    d_b = np.linalg.norm(R - L, axis=1)
    terms = {"C_B": baseline_cost(d_li, d_ri, d_b, config.alpha),
             "C_beta": vergence_cost(L, R, I, config.alpha),
             "C_T": _angle(r_l, r_li) + _angle(r_r, r_ri)}
    if occupied is None or occupied.n == 0:
        terms["C_G"] = np.zeros(len(L))
    else:
        G = occupied.data[occupied.query(I)[1]]
        terms["C_G"] = _angle(r_li, G - L) + _angle(r_ri, G - R)
    return terms


def stereo_cost(L, R, r_l, r_r, occupied: cKDTree | None,
                config: StereoCostConfig = StereoCostConfig()) -> np.ndarray:
    """C(L, R) (N,), eq. (9)."""
    t = stereo_terms(L, R, r_l, r_r, occupied, config)
    return (config.sigma_b * t["C_B"] + config.sigma_beta * t["C_beta"]
            + config.sigma_t * t["C_T"] + t["C_G"])
