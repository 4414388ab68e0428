"""explore: deciding where to go. What the planners share lives here (candidate views and
the rendering-quality heuristic, floor plans, the navigation grid, A* and path
simplification); each seed system's planner is a sub-package: `explore.vueplan` (VuePlan,
Blaer & Allen) and `explore.scenic` (the Scenic Route Planner)."""
