"""localization: pose estimation — motion models, the particle filter with rendered-view
likelihoods, the feature-based localiser, estimates and their uncertainty."""
