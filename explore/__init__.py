"""explore: deciding where to go — candidate views and their scores, grids and A*,
VuePlan view planning, roadmaps and tours, voxel maps, the scenic route planner."""
