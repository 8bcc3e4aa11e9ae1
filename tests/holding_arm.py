"""What the armed soft arm measures while it holds still in core's control cycle: the correlated
noise (the controller acts on the motion capture's) that the arm view's dead band must hold
back, shared by its test and ``benchmarks/dead_band_noise.py --closed-loop``."""

from __future__ import annotations

import numpy as np

from core.control.grasp_place import immediate
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack


def holding_kappa(robot, seed: int, seconds: float, every: int = 3
                  ) -> tuple[np.ndarray, bool]:
    """(the measured curvatures (n, N) at every ``every``-th tick of ``seconds`` of 100 Hz ticks
    after arming where a measurement came (none while a marker dropped out), whether the arm
    was armed at every tick) of ``robot`` armed and holding in ``SimLoop`` with ``seed``."""
    loop = SimLoop(SoftArmSim(robot, seed=seed),
                   ControlStack(robot, 0.01, immediate(lambda req: None)), 0.01)
    loop.run(0.05)
    loop.arm()
    measured, armed = [], True
    for k in range(round(seconds * 100)):
        control = loop.tick()
        armed = armed and control is not None and control.armed
        if k % every == 0 and control is not None and control.kappa_meas is not None:
            measured.append(control.kappa_meas.copy())
    return np.array(measured), armed
