"""A right-quadrant object grasped and placed end to end on the simulated arm through core's
control cycle (settle, plan, approach, grasp, move to the bin, release), held by the right finger.

Independent expectations: while the arm carries it, the simulator holds the object in the right
finger's pocket -- its centre in the gripper frame at -(2 g_off + r) across the gripper (the
mirror image of the paper's left grasp), along it within the finger, still -- and after the release it lies at the straight bin's
right pocket computed by hand (base at the origin heading +y: ``(2 g_off + r, N L + w_along)``).
"""

import numpy as np

from core import robots
from core.control.grasp_place import immediate
from core.control.planner_spec import plan_request
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.control.trials import paper_locations
from core.planning.sides import plan_grasp_sided

ARM = robots.load("soft-arm")
G = ARM.gripper
R = ARM.capture.nominal_object_radius
# (planning passes within the settling tick: the planner here answers at once)
ORDER = ["settling", "approach", "grasp", "move_to_bin", "release", "released"]


def test_a_right_quadrant_object_is_grasped_by_the_right_finger_and_released_at_the_bin():
    x, y = paper_locations()["D"]
    spot = (-x, y)  # spot D mirrored across the base line: right of the arm
    assert spot[0] > 0 and base_heading_is_plus_y()
    sim = SoftArmSim(ARM, seed=3)
    sim.place_object(*spot, R)
    stack = ControlStack(ARM, 0.01, immediate(
        lambda req: plan_request(plan_grasp_sided, ARM, req)))
    loop = SimLoop(sim, stack, 0.01)
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    loop.start_task()
    phases, grips = [], []
    for _ in range(round(150 / 0.01)):
        c = loop.tick()
        if c is None:
            continue
        if not phases or phases[-1] != c.phase:
            phases.append(c.phase)
        if c.phase == "move_to_bin" and sim.captured:
            grips.append(sim.obj.grip.copy())
        if c.phase in ("released", "stopped"):
            break
    assert phases == ORDER, (phases, stack.machine.reason)
    assert stack.machine.plan.side == "right" and stack.machine.closing_side == "right"
    # Carried in the right finger's pocket all the way to the bin.
    grips = np.array(grips)
    assert len(grips) > 100
    np.testing.assert_allclose(grips[:, 1], -(2 * G.g_off + R), atol=0.006)
    assert np.all((grips[:, 0] > 0.0) & (grips[:, 0] < G.length))  # within the finger's span
    assert np.ptp(grips, axis=0).max() < 0.002  # held still: it does not slip on the way
    # Released: out of the gripper, at the straight bin's right pocket.
    assert not sim.captured
    drop = np.array([2 * G.g_off + R, ARM.n_segments * ARM.segment_length + G.w_off_along])
    assert np.hypot(*(sim.obj.xy - drop)) < ARM.bin.drop_radius_m
    assert np.hypot(*(sim.obj.xy - spot)) > 0.1  # it really moved


def base_heading_is_plus_y():
    return np.allclose(ARM.base_pose, (0.0, 0.0, np.pi / 2))
