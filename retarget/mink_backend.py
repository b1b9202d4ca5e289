"""The mink backend: the retargeter's objectives as mink tasks, mink's configuration and
self-collision limits and our hand–object, coupling and wrist-speed rows, ``mink.solve_ik``."""

from __future__ import annotations

import mink
import numpy as np

from retarget.limits import CouplingLimit
from retarget.state import RobotState


class MinkSolver:
    """The mink backend: our objectives as mink tasks, mink's limits, ``mink.solve_ik``."""

    def __init__(self, rt):
        self.rt = rt
        m = rt.scene.model
        self.configuration = mink.Configuration(m)
        # One MjData for mink, our kinematics and the collision queries: the object pose set
        # on the scene is the one mink's collision limit sees.
        self.configuration.data = rt.scene.data
        self.kin = rt.kin
        cl = mink.ConfigurationLimit(m, gain=1.0)
        # The kinematic solution's ranges (inside by the joint limit margin), as on the
        # Pinocchio backend: the hand's joints are the scene's first qpos entries.
        lim = m.jnt_limited[: rt.nq].astype(bool)
        cl.lower[: rt.nq][lim] = rt._solve_lower[lim]
        cl.upper[: rt.nq][lim] = rt._solve_upper[lim]
        self.limits = [cl]
        if rt.collision is not None:
            # Our hand–object rows, as on the Pinocchio backend: per-pair margins (the table's
            # clearance, the clearance of links the human keeps off the object) and the further
            # contacts mj_collision reports, which mink's CollisionAvoidanceLimit (one minimum
            # distance, closest points only) cannot express.
            self.limits.append(self._rows(rt.collision))
        if rt.self_collision is not None:
            # One mink pair per self-collision pair: grouping all hand geoms would also pair
            # links of one finger and the resting contacts the hand excludes.
            name = lambda g: m.geom(g).name  # noqa: E731
            self.limits.append(
                mink.CollisionAvoidanceLimit(
                    m,
                    geom_pairs=[([name(a)], [name(b)]) for a, b in rt.self_pairs],
                    gain=1.0,
                    minimum_distance_from_collisions=-rt.cfg.self_collision.margin,
                    collision_detection_distance=rt.cfg.self_collision.distmax,
                )
            )
        self.constraints = [mink.EqualityConstraintTask(m, cost=1.0)] if m.neq else []
        coupling = next((c for c in rt.limits if isinstance(c, CouplingLimit)), None)
        if coupling is not None and coupling.ranges:
            # Limited fixed tendons (Shadow's distal coupling): mink has no tendon limit.
            self.limits.append(self._rows(coupling))
        self.frame_dt = 1.0 / 30.0  # the frame's time step (FrameSpeedLimit's band)

    def _rows(self, limit):
        """One of our limits as a mink limit: its rows ``G Δq ≤ h`` and its finite box
        bounds, at the configuration mink solves at (``Δq = v·dt``)."""
        kin, nq, solver = self.kin, self.rt.nq, self

        class _Rows(mink.Limit):
            def compute_qp_inequalities(self, configuration, dt):
                state = RobotState(q=configuration.q[:nq].copy(), kin=kin, dt=solver.frame_dt)
                G, h = limit.inequalities(state)
                box = limit.bounds(state)
                if box is not None:
                    eye = np.eye(nq)
                    lo, hi = box
                    up, dn = np.isfinite(hi), np.isfinite(lo)
                    G = np.concatenate([G, eye[up], -eye[dn]])
                    h = np.concatenate([h, hi[up], -lo[dn]])
                if not G.shape[0]:
                    return mink.Constraint()
                return mink.Constraint(G=G * dt, h=h)

        return _Rows()

    def _task(self, objective):
        kin = self.kin

        class _Task(mink.Task):
            def __init__(self):
                super().__init__(cost=np.ones(1))

            def _state(self, configuration):
                return RobotState(q=configuration.q.copy(), kin=kin)

            def compute_error(self, configuration):
                return objective.error(self._state(configuration))

            def compute_jacobian(self, configuration):
                return objective.jacobian(self._state(configuration))

            def compute_qp_residual(self, configuration):
                # mink stacks (√W J, −√W e) of all tasks: H = JᵀWJ, c = JᵀWe, as ours.
                s = self._state(configuration)
                e = objective.error(s)
                if e.size == 0:
                    return np.zeros((0, s.nv)), np.zeros(0), 0.0
                sw = np.sqrt(objective.weights(e.shape[0]))
                return sw[:, None] * objective.jacobian(s), -sw * e, 0.0

            def compute_qp_objective(self, configuration):
                H, c = objective.qp_terms(self._state(configuration))
                return mink.Objective(H, c)

        return _Task()

    def solve(self, q: np.ndarray, iterations: int, frame=(), dt: float = 1.0 / 30.0):
        """``iterations`` mink steps from ``q``; ``frame``: per-frame limits of ours (the
        wrist's speed bound), ``dt`` the frame's time step."""
        conf = self.configuration
        conf.update(q)
        self.frame_dt = dt
        tasks = [self._task(o) for o in self.rt._objectives()]
        limits = [*self.limits, *(self._rows(x) for x in frame)]
        cfg = self.rt.cfg

        def step(limits):
            v = mink.solve_ik(
                conf, tasks, dt=1.0, solver=cfg.solver.qp_solver, damping=cfg.solver.damping,
                limits=limits, constraints=self.constraints or None,
            )  # fmt: skip
            conf.integrate_inplace(v, 1.0)
            return v

        for _ in range(iterations):
            if np.abs(step(limits)).max() < cfg.solver.step_tolerance:
                break
        # The Pinocchio backend's end-of-step check (``_solve_frame``): while the solution is
        # deeper than the margins, more steps in trust regions 4× smaller each time (Allegro's
        # proximal box on the cube's face flipped between two rows: 3–4 mm deep every other
        # frame without them).
        for fixes in range(1, cfg.solver.max_feasibility_iterations + 1):
            if not self.rt._violates_margins(conf.q[: self.rt.nq]):
                break
            step([*limits, self._rows(self.rt._trust_region(fixes))])
        return conf.q.copy()
