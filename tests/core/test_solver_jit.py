"""The compiled Newton kernel (core.planning.solver_jit) solves like the pure-Python SQP.

Its logic is checked without a compiler (numba's NUMBA_DISABLE_JIT runs the kernel's source as
Python, in a subprocess so this process's numba is untouched); the compiled kernel itself is
compared where it is already in numba's disk cache (compiling takes several seconds, so the
test does not compile it).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]

# Plans on a grid and on random objects of both quadrants, and single solves from a straight arm
# (some must hand over to the active-set loop: far starts hit the bounds), by the kernel and by
# the pure-Python path; printed as JSON.
_SCRIPT = r"""
import json, os, sys
import numpy as np
from core import robots
from core.planning import grasp_solver as gs
from core.planning.arm_model import ArmModel
from core.planning.grasp import GraspPlanner, GraspRefused

arm = robots.load("soft-arm")
model = ArmModel.from_robot(arm)
rng = np.random.default_rng(17)
objs = [((x, y), r) for x in (-0.25, -0.15, -0.05) for y in (0.1, 0.2, 0.3) for r in (0.01, 0.02)]
objs += [((s * rng.uniform(0.02, 0.4), rng.uniform(0.05, 0.4)), rng.uniform(0.01, 0.025))
         for s in (-1, 1) for _ in range(8)]
offs = [complex(0.035, 0.03 + ra) for ra in (0.02, 0.08, 0.15)]
centers = [complex(rng.uniform(-0.35, 0.35), rng.uniform(0.02, 0.4)) for _ in range(12)]

def run():
    gs.compiled_kernel.cache_clear()
    used = gs.compiled_kernel() is not None
    planner = GraspPlanner(arm)
    plans = []
    for c, r in objs:
        try:
            p = planner.plan(np.zeros(6), c, r)
        except GraspRefused as exc:
            plans.append(exc.reason)
            continue
        plans.append(dict(ok=p.success, kappas=p.kappas.tolist(), status=list(p.status)))
    solves = []
    for c in centers:
        for off in offs:
            s = gs.solve(model, c, off, np.zeros(6), np.zeros(6), np.ones(6), tangent=True)
            solves.append(dict(status=s.status, kappa=s.kappa.tolist(), it=s.iterations,
                               dk=None if s.dkappa_dr is None else s.dkappa_dr.tolist()))
    return dict(used=used, plans=plans, solves=solves)

os.environ["GRASP_SOLVER_JIT"] = "1"
fast = run()
os.environ["GRASP_SOLVER_JIT"] = "0"
slow = run()
print(json.dumps(dict(fast=fast, slow=slow)))
"""


def _compare(out: dict) -> None:
    fast, slow = out["fast"], out["slow"]
    assert fast["used"] and not slow["used"]
    assert len(fast["plans"]) == len(slow["plans"])
    solved = 0
    for a, b in zip(fast["plans"], slow["plans"]):
        if isinstance(b, str):
            assert a == b                      # the same refusal
            continue
        assert a["ok"] == b["ok"] and a["status"] == b["status"]
        np.testing.assert_allclose(a["kappas"], b["kappas"], atol=1e-6)
        solved += b["ok"]
    assert solved >= 10
    for a, b in zip(fast["solves"], slow["solves"]):
        assert a["status"] == b["status"]
        np.testing.assert_allclose(a["kappa"], b["kappa"], atol=1e-6)
        assert abs(a["it"] - b["it"]) <= 1
        if b["dk"] is not None and a["dk"] is not None:
            np.testing.assert_allclose(a["dk"], b["dk"], rtol=1e-5, atol=1e-5)


def _run(env: dict) -> dict:
    proc = subprocess.run([sys.executable, "-c", _SCRIPT], cwd=ROOT, capture_output=True,
                          text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT), **env})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_kernel_logic_matches_the_python_sqp():
    _compare(_run({"NUMBA_DISABLE_JIT": "1"}))


def test_compiled_kernel_matches_the_python_sqp():
    from core.planning.solver_jit import compiled_on_disk

    if not compiled_on_disk():
        pytest.skip("the compiled kernel is not in numba's disk cache (GRASP_SOLVER_JIT=1 "
                    "builds it on first use)")
    _compare(_run({}))
