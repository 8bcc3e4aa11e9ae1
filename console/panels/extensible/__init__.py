"""The extensible arm's panels: tip target, paths, obstacles, repeatability."""
