"""The map of the Scenic Route Planner (Mendez et al., "Scenic Route Planner: opportunistic
collaboration of cameras", Sec. 3.1): a voxel store V = Vo ∪ Ve ∪ Vu of *occupied* voxels
(they hold reconstructed points), *empty* voxels (space a camera may occupy, carved along
camera-to-point rays) and *unobserved* voxels (everything else).

Each point is a 3-D Gaussian (mean, covariance). Data association is a lookup: a new point
is matched to the stored point in the same association cell (a finer voxel key, `assoc_m`);
a match is updated with the new observation (information-form fusion: Λ = Σ Σ_i⁻¹,
η = Σ Σ_i⁻¹ x_i, x = Λ⁻¹ η); a point with no match is added. The paper uses an octree; a
dense int8 grid plus sorted integer keys does the same lookups, vectorised.

Frames and units: world metres, z up. Voxel (i, j, k) spans origin + voxel_m * [i, i+1) x
[j, j+1) x [k, k+1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

UNOBSERVED, EMPTY, OCCUPIED = np.int8(0), np.int8(1), np.int8(2)


@dataclass(frozen=True)
class MapConfig:
    voxel_m: float = 0.1
    """Edge of an occupancy voxel (metres): the unit of Vo / Ve / Vu and of ray casting."""
    assoc_m: float = 0.025
    """Edge of a data-association cell (metres): points falling in one cell are one point."""
    carve_stop_m: float = 0.15
    """Free space is carved along each camera-to-point ray up to this distance before the point."""
    min_info: float = 1e-9
    """Regulariser added to information matrices (1/m^2) so fusion stays invertible."""


@dataclass
class ScenicMap:
    """origin (3,) metres: lower corner; state (nx, ny, nz) int8 in {UNOBSERVED, EMPTY, OCCUPIED};
    keys (N,) int64 association-cell keys, sorted; info (N, 3, 3) point information matrices
    (1/m^2); eta (N, 3) information vectors; n_obs (N,) observations fused into each point."""

    config: MapConfig
    origin: np.ndarray
    state: np.ndarray
    keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    info: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    eta: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    n_obs: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    _cache: dict = field(default_factory=dict, repr=False)

    @classmethod
    def covering(cls, lo, hi, config: MapConfig = MapConfig()) -> "ScenicMap":
        """An all-unobserved map covering the box [lo, hi] (metres)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        shape = np.maximum(np.ceil((hi - lo) / config.voxel_m).astype(int), 1)
        return cls(config, lo, np.full(tuple(shape), UNOBSERVED, np.int8))

    def cached(self, key, compute):
        """`compute()` of this map, computed once per `key` until the map changes (every
        update clears the cache): for quantities derived from the map by other modules."""
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]

    # --- geometry of the grid -------------------------------------------------------
    @property
    def voxel_m(self) -> float:
        return self.config.voxel_m

    def voxel_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Integer voxel indices (N, 3) of world points (N, 3) and whether each is inside."""
        ijk = np.floor((np.asarray(points) - self.origin) / self.voxel_m).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < self.state.shape), axis=-1)
        return ijk, inside

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """Voxel state of world points (..., 3); UNOBSERVED outside the grid."""
        ijk, inside = self.voxel_of(points)
        ijk = np.where(inside[..., None], ijk, 0)
        s = self.state[ijk[..., 0], ijk[..., 1], ijk[..., 2]]
        return np.where(inside, s, UNOBSERVED)

    def voxel_centres(self, ijk: np.ndarray) -> np.ndarray:
        return self.origin + (np.asarray(ijk) + 0.5) * self.voxel_m

    # --- points --------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.keys)

    @property
    def means(self) -> np.ndarray:
        """(N, 3) fused point positions, metres."""
        if "means" not in self._cache:
            self._cache["means"] = np.linalg.solve(self.info, self.eta[..., None])[..., 0]
        return self._cache["means"]

    @property
    def covariances(self) -> np.ndarray:
        """(N, 3, 3) fused point covariances, m^2."""
        if "covs" not in self._cache:
            self._cache["covs"] = np.linalg.inv(self.info)
        return self._cache["covs"]

    def principal_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Largest eigenvalue λ_p (N,) m^2 and its unit eigenvector e_p (N, 3) per point."""
        if "eig" not in self._cache:
            w, v = np.linalg.eigh(self.covariances)
            self._cache["eig"] = (w[:, -1], v[:, :, -1])
        return self._cache["eig"]

    def points_by_voxel(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR view of Pv: (order (N,) point indices grouped by voxel, start (nvox,), count
        (nvox,)) over the flat voxel index, for the ψ average of Sec. 3.2.2."""
        if "csr" not in self._cache:
            ijk, inside = self.voxel_of(self.means)
            flat = np.ravel_multi_index(tuple(np.where(inside[:, None], ijk, 0).T), self.state.shape)
            flat = np.where(inside, flat, -1)
            order = np.argsort(flat, kind="stable")
            order = order[flat[order] >= 0]
            count = np.bincount(flat[order], minlength=self.state.size)
            start = np.r_[0, np.cumsum(count)[:-1]]
            self._cache["csr"] = (order, start, count)
        return self._cache["csr"]

    def occupied_centres(self) -> np.ndarray:
        """(M, 3) centres of the occupied voxels (Vo), metres."""
        if "occ" not in self._cache:
            self._cache["occ"] = self.voxel_centres(np.argwhere(self.state == OCCUPIED))
        return self._cache["occ"]

    # --- updates -------------------------------------------------------------------
    def insert(self, camera_centres: np.ndarray, points: np.ndarray, covs: np.ndarray) -> int:
        """Add an observation: points (N, 3) with covariances (N, 3, 3), each seen from
        camera_centres (N, 3). Carves Ve along the rays, associates and fuses the points,
        marks their voxels occupied. Returns how many were matched to existing points."""
        if len(points) == 0:
            return 0
        self.carve(camera_centres, points)
        n_matched = self._associate(points, covs)
        self._cache.clear()
        ijk, inside = self.voxel_of(self.means)
        ijk = ijk[inside]
        self.state[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = OCCUPIED
        self._cache.clear()
        return n_matched

    def _assoc_keys(self, points: np.ndarray) -> np.ndarray:
        c = np.floor((points - self.origin) / self.config.assoc_m).astype(np.int64) + 2**20
        return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]

    def _associate(self, points: np.ndarray, covs: np.ndarray) -> int:
        """Data association by cell lookup and information-form fusion (vectorised)."""
        new_info = np.linalg.inv(covs) + self.config.min_info * np.eye(3)
        new_eta = (new_info @ points[..., None])[..., 0]
        new_keys = self._assoc_keys(points)
        n_matched = int(np.isin(new_keys, self.keys).sum())
        keys = np.r_[self.keys, new_keys]
        uniq, inverse = np.unique(keys, return_inverse=True)
        info = np.zeros((len(uniq), 3, 3))
        eta = np.zeros((len(uniq), 3))
        n_obs = np.zeros(len(uniq), np.int64)
        np.add.at(info, inverse, np.r_[self.info, new_info])
        np.add.at(eta, inverse, np.r_[self.eta, new_eta])
        np.add.at(n_obs, inverse, np.r_[self.n_obs, np.ones(len(points), np.int64)])
        self.keys, self.info, self.eta, self.n_obs = uniq, info, eta, n_obs
        return n_matched

    def carve(self, camera_centres: np.ndarray, points: np.ndarray) -> None:
        """Mark unobserved voxels crossed by the rays camera -> point as empty (Ve), stopping
        `carve_stop_m` short of the point; occupied voxels stay occupied. All rays at once:
        samples every half voxel along every ray (one (N, S) array)."""
        seg = points - camera_centres
        length = np.linalg.norm(seg, axis=1)
        reach = np.maximum(length - self.config.carve_stop_m, 0.0)
        step = 0.5 * self.voxel_m
        n_steps = int(np.ceil(reach.max() / step)) + 1 if len(reach) else 0
        t = np.arange(n_steps) * step                                   # (S,) metres
        valid = t[None, :] <= reach[:, None]                            # (N, S)
        unit = seg / np.maximum(length, 1e-12)[:, None]
        samples = camera_centres[:, None, :] + t[None, :, None] * unit[:, None, :]
        ijk, inside = self.voxel_of(samples[valid])
        ijk = ijk[inside]
        cells = self.state[ijk[:, 0], ijk[:, 1], ijk[:, 2]]
        ijk = ijk[cells == UNOBSERVED]
        self.state[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = EMPTY
        self._cache.clear()

    def mark_empty_ball(self, centre: np.ndarray, radius_m: float) -> None:
        """Mark the unobserved voxels within `radius_m` of a camera centre empty: the space a
        camera stands in is free (how the initial poses enter Ve)."""
        lo, _ = self.voxel_of(np.asarray(centre) - radius_m)
        hi, _ = self.voxel_of(np.asarray(centre) + radius_m)
        lo, hi = np.maximum(lo, 0), np.minimum(hi + 1, self.state.shape)
        grid = np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)], indexing="ij"), -1)
        grid = grid.reshape(-1, 3)
        near = np.linalg.norm(self.voxel_centres(grid) - centre, axis=1) <= radius_m
        g = grid[near]
        sel = self.state[g[:, 0], g[:, 1], g[:, 2]] == UNOBSERVED
        g = g[sel]
        self.state[g[:, 0], g[:, 1], g[:, 2]] = EMPTY
        self._cache.clear()
