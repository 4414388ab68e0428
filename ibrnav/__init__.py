"""The `ibrnav` console script: the one place that imports all four packages."""
