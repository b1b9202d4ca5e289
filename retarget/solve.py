"""The per-frame solve: Gauss–Newton QP steps from a warm start, the end-of-step
feasibility re-steps in shrinking trust regions, and the solver's settings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from dexcanvas_core.checks import check_int
from retarget._checks import check_choice, check_range
from retarget._kernels import predicted_start
from retarget.errors import RetargetError
from retarget.limits import FrameSpeedLimit, VelocityLimit
from retarget.qp import QPSolveError, build_qp, solve_qp
from retarget.state import RobotState

Backend = Literal["pinocchio", "mink"]


@dataclass(frozen=True, kw_only=True)
class SolverConfig:
    """The per-frame QP solve (``docs/method.md#the-solver-loop``)."""

    backend: Backend = "pinocchio"
    """``pinocchio`` (our QP on Pinocchio kinematics) or ``mink`` (mink on MuJoCo). Default
    ``pinocchio``."""
    iterations: int = 3
    """Most Gauss–Newton iterations per frame (warm-started from the previous frame). Default
    3."""
    first_frame_iterations: int = 30
    """Most iterations on the first frame (starting from the open posture). Default 30."""
    step_tolerance: float = 5e-3
    """A frame's iterations stop once the largest joint step falls below this [rad or m]; 0
    always runs the full count. Default 5e-3."""
    warm_start_extrapolate: bool = True
    """Start each frame's iterations from a prediction (the wrist moved as the human's, the
    finger joints at their last velocity) instead of the previous solution. Default True."""
    max_feasibility_iterations: int = 3
    """Extra iterations a frame may take while its solution penetrates the object (or one
    finger another) by more than the margin + 0.5 mm. Default 3."""
    qp_solver: str = "daqp"
    """The ``qpsolvers`` solver. Default ``daqp``."""
    damping: float = 1e-5
    """Levenberg–Marquardt damping of the step. Default 1e-5."""

    def __post_init__(self):
        check_choice(self, "backend", Backend)
        for name in ("iterations", "first_frame_iterations"):
            check_int(f"{type(self).__name__}.{name}", getattr(self, name), error=RetargetError)
        if self.iterations < 1 or self.first_frame_iterations < 1:
            raise RetargetError(
                f"SolverConfig.iterations and first_frame_iterations must be >= 1, got "
                f"{self.iterations} and {self.first_frame_iterations}"
            )
        if self.max_feasibility_iterations < 0:
            raise RetargetError(
                "SolverConfig.max_feasibility_iterations must be >= 0, got "
                f"{self.max_feasibility_iterations}"
            )
        check_range(self, "step_tolerance", unit="rad or m")


class FrameSolver:
    """The :class:`retarget.retargeter.Retargeter`'s per-frame solve (a mixin: it reads the
    retargeter's objectives, limits, kinematics and config)."""

    def _objectives(self):
        objs = [self.keypoints, self.posture, self.smooth]
        if any(self.wrist.weight):  # (a hand with wrist_weight 0: no wrist term to build)
            objs.insert(0, self.wrist)
        if self.vec_human:
            objs.append(self.vectors)
        if self.cfg.contacts.enabled and self.contacts is not None:
            objs.append(self.contacts)
        return objs

    def _solve_frame(
        self,
        q: np.ndarray,
        iterations: int,
        timestamp: np.ndarray,
        t: int,
        q_prev: np.ndarray | None = None,
    ) -> np.ndarray:
        dt = float(timestamp[t] - timestamp[t - 1]) if t > 0 else 1.0 / 30.0
        frame = []
        if q_prev is not None and np.isfinite(self.cfg.velocity.max_wrist_speed):
            frame = [FrameSpeedLimit(q_prev, self._wrist_speed)]
        if self._mink is not None:
            return self._mink.solve(q, iterations, frame, dt)
        limits = [*self.limits, self._velocity, *frame] if t > 0 else self.limits
        objectives = self._objectives()
        extra = self.cfg.solver.max_feasibility_iterations
        i = fixes = 0
        while True:
            self.kin.forward(q)
            state = RobotState(q=q, kin=self.kin, dt=dt)
            try:
                dq = self._solve_step(state, objectives, limits)
            except QPSolveError:
                if not fixes:
                    raise
                # The trust region is too small to back out as far as the rows ask: keep the
                # last solution (deeper than the margin, shallower than without the re-steps).
                return q
            q = q + dq
            i += 1
            if not fixes and i < iterations and np.abs(dq).max() >= self.cfg.solver.step_tolerance:
                continue
            # The rows are linear in the step; a finger sliding or turning on a curved surface
            # (or a box fingertip rolling onto its edge) can end the step deeper than the
            # margin, or inside a clearance (Shadow's middle proximal swinging round the
            # example cube2's edge from 24 mm off, outside every row: 0.2 mm from the cube
            # instead of 2). Check the end point and take more steps while it violates a
            # margin, each in a trust region 4× smaller than the last: at full speed the
            # linearisation can flip between two rows every step (LEAP's index finger on the
            # built-in cylinder2/extension_type: 0.17 rad steps, 2.2 mm deep after 10 of them).
            if fixes >= extra or not self._violates_margins(q):
                return q
            fixes += 1
            limits = [*self.limits, self._trust_region(fixes), *frame]

    def _trust_region(self, fixes: int) -> VelocityLimit:
        """The velocity bound of an end-of-step re-step (both backends): ``fixes`` (≥ 1)
        times 4× smaller than the per-iterate bound."""
        return VelocityLimit(self.cfg.velocity.max_joint_speed * 0.25**fixes)

    def _solve_step(self, state: RobotState, objectives, limits) -> np.ndarray:
        """One QP step. If it is infeasible because a penetrating pair cannot back out as
        far as its row asks (joint limits in the way; a random Allegro pose in the round-trip
        test), solve again with the collision rows only forbidding deeper penetration."""
        try:
            return solve_qp(
                build_qp(state, objectives, limits, self.cfg.solver.damping),
                self.cfg.solver.qp_solver,
            )
        except QPSolveError:
            lims = [x for x in (self.collision, self.self_collision) if x is not None]
            if not lims:
                raise
            for x in lims:
                x.hold_only = True
            try:
                return solve_qp(
                    build_qp(state, objectives, limits, self.cfg.solver.damping),
                    self.cfg.solver.qp_solver,
                )
            finally:
                for x in lims:
                    x.hold_only = False

    def _warm_start(
        self, Q_last: np.ndarray, wq: np.ndarray, active: np.ndarray, t: int
    ) -> np.ndarray:
        """Frame ``t``'s starting point from the last two solutions ``Q_last`` (2, nq), the
        human wrist's joint coordinates at ``t − 1`` and ``t`` and the contact flags: the
        wrist moves as the human's did, the fingers at their last velocity unless a contact
        switched in the last two frames (its jump is no velocity to go on with). A prediction
        deeper in the object than the margins falls back to the last solution (more than one
        step may be needed to undo it: the example cube2/tripod, Shadow, 17 mm deep). The
        prediction is clipped to the solver's joint ranges (inside the servos' by
        ``joint_limits.margin``)."""
        q0 = predicted_start(Q_last, wq, active, t, self._solve_lower, self._solve_upper)
        return Q_last[1] if self._too_deep(q0) or self._breaks_couplings(q0) else q0

    COUPLING_TOLERANCE = 5e-3
    """A warm-start prediction whose joint couplings are off by more than this [rad or m] falls
    back to the last solution (``_warm_start``)."""

    def _breaks_couplings(self, q: np.ndarray) -> bool:
        """Whether ``q`` breaks one of the model's joint couplings by more than
        :attr:`COUPLING_TOLERANCE`. The prediction is clipped to the joint ranges joint by
        joint, so a driving joint stopped at its limit while the joint it drives went on
        breaks their coupling; the QP's equality rows then ask more than one iterate's
        velocity bound allows to undo it, and the frame's QP is infeasible."""
        c = self._coupling
        if not c or not c.rows:
            return False
        _, b = c.equalities(RobotState(q=q, kin=self.kin))
        return bool(b.size) and float(np.abs(b).max()) > self.COUPLING_TOLERANCE

    def _too_deep(self, q: np.ndarray) -> bool:
        """Whether ``q`` is deeper than a collision limit's margin + 0.5 mm anywhere (one
        sweep, which the frame's first iterate then reuses)."""
        for lim in (self.collision, self.self_collision):
            if lim is not None and lim.min_distance(q) < -(lim.margin + 5e-4):
                return True
        return False

    def _violates_margins(self, q: np.ndarray) -> bool:
        """Whether some pair at ``q`` is closer than its margin allows, by more than 0.5 mm:
        deeper than the penetration margin, or inside a clearance (a link the human keeps
        clear of the object, the table).

        Only the pairs near at the last linearisation are checked
        (``CollisionLimit.near_violation``: a step from farther away would need a joint speed
        the velocity rows rarely allow)."""
        for lim in (self.collision, self.self_collision):
            if lim is not None and lim.near_violation(q) < -5e-4:
                return True
        return False
