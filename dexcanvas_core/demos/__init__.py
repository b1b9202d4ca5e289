"""Generated hand–object demonstrations for every feasible (object, manipulation type) pair.

The pipeline, one module per concept (object shapes are in :mod:`dexcanvas_core.objects.geometry`,
the hand's kinematics and capsules in :mod:`dexcanvas_core.mano.hand_model`):

* ``feasibility`` — which pairs a human hand can perform, and why (:func:`feasibility_table`);
* ``operators`` — five hand sizes (:data:`OPERATORS`);
* ``grasp`` — grasp synthesis by optimisation on the skeleton (:func:`solve_grasp`);
* ``motions`` — minimum-jerk scripts: pick-and-place, rolling, sliding, rotation, transfer;
* ``checks`` — plausibility checks of a trajectory (:func:`check_trajectory`);
* ``demo`` — one checked demonstration (:func:`generate_demo`);
* ``build`` — datasets and the built-in set (:func:`build_demos`, :func:`run_build`).

>>> from dexcanvas_core.demos import generate_demo
>>> demo = generate_demo("cube2/tripod", "operator2", seed=1)  # doctest: +SKIP
>>> demo.report.passed, demo.trajectory.fps  # doctest: +SKIP
(True, 120.0)
"""

from dexcanvas_core.demos.build import (
    BuildConfig,
    BuildReport,
    DemoRecord,
    build_demos,
    report_path,
    run_build,
)
from dexcanvas_core.demos.builtin_set import build_builtin, builtin_pairs, builtin_plan
from dexcanvas_core.demos.checks import (
    CheckLimits,
    CheckResult,
    ContactInterval,
    PlausibilityReport,
    check_trajectory,
)
from dexcanvas_core.demos.demo import DEMOS_VERSION, Demo, DemoError, generate_demo
from dexcanvas_core.demos.feasibility import (
    Feasibility,
    feasibility,
    feasibility_table,
    feasible_pairs,
    spread_pairs,
)
from dexcanvas_core.demos.grasp import Grasp, solve_grasp
from dexcanvas_core.demos.grasp_specs import GRASP_SPECS, GraspSpec
from dexcanvas_core.demos.operators import OPERATORS, Operator, operator

__all__ = [
    "DEMOS_VERSION",
    "GRASP_SPECS",
    "OPERATORS",
    "BuildConfig",
    "BuildReport",
    "CheckLimits",
    "CheckResult",
    "ContactInterval",
    "Demo",
    "DemoError",
    "DemoRecord",
    "Feasibility",
    "Grasp",
    "GraspSpec",
    "Operator",
    "PlausibilityReport",
    "build_builtin",
    "build_demos",
    "builtin_pairs",
    "builtin_plan",
    "check_trajectory",
    "feasibility",
    "feasibility_table",
    "feasible_pairs",
    "generate_demo",
    "operator",
    "report_path",
    "run_build",
    "solve_grasp",
    "spread_pairs",
]
