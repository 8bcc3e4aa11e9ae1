"""The soft arm's panels: objects, grasp planner, waypoints, control, experiments."""
