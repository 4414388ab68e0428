"""explore.vueplan: VuePlan (Blaer & Allen 2009), two-phase view planning for site scanning:
Phase I views from the 2-D map (art-gallery with sensor constraints), the Voronoi roadmap
and TSP tour between them, the z-buffer scan simulator, and Phase II next-best views on a
voxel space."""

from explore.vueplan.phase1 import Phase1Config, Phase1Result, plan_phase1
from explore.vueplan.phase2 import Phase2Config, SurfaceCoverage, count_visible, ground_candidates, plan_phase2
from explore.vueplan.roadmap import Roadmap, build_roadmap
from explore.vueplan.scan_simulator import Scan, ScanConfig, simulate_scan
from explore.vueplan.site import load_site
from explore.vueplan.tour import Tour, plan_tour
from explore.vueplan.voxel_grid import VoxelGrid, boundary_unseen, insert_scan

__all__ = ["Phase1Config", "Phase1Result", "Phase2Config", "Roadmap", "Scan", "ScanConfig", "SurfaceCoverage",
           "Tour", "VoxelGrid", "boundary_unseen", "build_roadmap", "count_visible", "ground_candidates",
           "insert_scan", "load_site", "plan_phase1", "plan_phase2", "plan_tour", "simulate_scan"]
