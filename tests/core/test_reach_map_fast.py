"""The coarse-to-fine reachability map stays the planner's truth, with far fewer plans.

The map plans every 4th cell first and a finer cell only where the coarser cells around it
disagree. Independent check: the planner's own answer (``cell_status``, the same planner the
map uses) at random cells agrees with the map except within one cell of a boundary between
outcomes; and the number of plans is well below one per candidate cell.
"""

import numpy as np
import pytest

from core import robots
from core.planning import reachability as reach_mod
from core.planning.grasp import GraspPlanner
from core.robot_schema import tomllib
from core.planning.reachability import (FAILS, PLANNABLE, UNREACHABLE, cell_status, grid_axis,
                                        map_planner, reachability_map)

# The paper's single finger (closing to the left): its right quadrant is where Algorithm 1
# finds a final pose but fails the approach (FAILS), the outcome this test must meet.
_SHIPPED = tomllib.loads(robots.load("soft-arm").source.read_text())
ROBOT = robots.parse({**_SHIPPED, "gripper": {**_SHIPPED["gripper"], "fingers": "left"}},
                     robots.load("soft-arm").source)
RADIUS = ROBOT.capture.nominal_object_radius
X, Y, STEP = (-0.30, 0.30), (0.10, 0.50), 0.02


@pytest.fixture(scope="module")
def fast(request):
    calls = []
    original = GraspPlanner.plan

    def counted(self, *args, **kwargs):
        calls.append(args[1])
        return original(self, *args, **kwargs)

    mp = pytest.MonkeyPatch()
    mp.setattr(GraspPlanner, "plan", counted)
    fractions = []
    try:
        reach = reachability_map(ROBOT, RADIUS, X, Y, STEP, levels=2, progress=fractions.append)
    finally:
        mp.undo()
    return reach, len(calls), fractions


def near_boundary(status, i, j):
    block = status[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2]
    return bool((block != status[i, j]).any())


def test_fast_map_agrees_with_the_planner_at_random_cells_off_boundaries(fast):
    reach, _, _ = fast
    planner = map_planner(ROBOT)
    rng = np.random.default_rng(7)
    ny, nx = reach.status.shape
    checked = {UNREACHABLE: 0, PLANNABLE: 0, FAILS: 0}
    for i, j in zip(rng.integers(0, ny, 60), rng.integers(0, nx, 60)):
        if near_boundary(reach.status, i, j):
            continue
        truth = cell_status(planner, np.zeros(ROBOT.n_segments), reach.xs[j], reach.ys[i], RADIUS)
        assert reach.status[i, j] == truth, (reach.xs[j], reach.ys[i])
        checked[truth] += 1
    # Not vacuous: interior cells of both reachable outcomes and of the unreachable area.
    assert checked[UNREACHABLE] >= 3 and checked[PLANNABLE] >= 3 and checked[FAILS] >= 1


def test_fast_map_plans_fewer_cells_than_it_decides(fast):
    reach, plans, _ = fast
    xs, ys = grid_axis(*X, STEP), grid_axis(*Y, STEP)
    candidates = reach_mod._candidates(ROBOT, map_planner(ROBOT).model, RADIUS, xs, ys, 40000,
                                       0.02)
    assert plans < 0.7 * candidates.sum()
    assert (reach.status[~candidates] == UNREACHABLE).all()


def test_progress_rises_to_one(fast):
    _, plans, fractions = fast
    assert len(fractions) >= plans
    assert np.all(np.diff(fractions) >= 0) and fractions[-1] == 1.0 and fractions[0] < 0.5


def test_grid_covers_the_extent_exactly():
    xs = grid_axis(-0.482, 0.482, 0.02)
    assert xs[0] == -0.482 and xs[-1] == 0.482 and np.diff(xs).max() <= 0.02 + 1e-12
    np.testing.assert_allclose(grid_axis(-0.3, 0.1, 0.1), [-0.3, -0.2, -0.1, 0.0, 0.1], atol=1e-12)
