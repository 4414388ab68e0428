"""ibr.proxy: proxy geometry from posed photos: SIFT triangulation with known poses,
plane-sweep dense points, normals, a Poisson mesh, and COLMAP SfM for unposed photos."""

from ibr.proxy.dense_points import DenseConfig, dense_points
from ibr.proxy.normals import estimate_normals, remove_outliers
from ibr.proxy.plane_sweep import PlaneSweep, PlaneSweepConfig
from ibr.proxy.poisson import PoissonConfig, poisson_mesh
from ibr.proxy.proxy_geometry import Proxy, ProxyConfig, build_proxy
from ibr.proxy.sfm import load_unposed
from ibr.proxy.triangulation import TriangulationConfig, sift_features, triangulate_views

__all__ = ["DenseConfig", "PlaneSweep", "PlaneSweepConfig", "PoissonConfig", "Proxy", "ProxyConfig",
           "TriangulationConfig", "build_proxy", "dense_points", "estimate_normals", "load_unposed", "poisson_mesh",
           "remove_outliers", "sift_features", "triangulate_views"]
