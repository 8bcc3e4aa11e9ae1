"""The 3D view's layers: the arms drawn by pose, the table, the plan, obstacles, shading."""
