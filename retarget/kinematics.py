"""One kinematic model for every backend: a Pinocchio model derived from a compiled ``MjModel``.

Each robot hand is built once as a MuJoCo model (``retarget.hands``); the Pinocchio model is
derived from it here, so the QP solver (Pinocchio), mink (MuJoCo) and the re-simulation all see
the same joints, body placements and sites. Supported joints: hinge and slide (the hands and
their 6-DoF floating wrists use nothing else); a body may carry several joints (MuJoCo composes
them in order about their anchors ``jnt_pos``), which become a chain of Pinocchio joints.

Configuration vectors use MuJoCo's ``qpos`` order (``nq == nv``: hinge/slide only); Pinocchio
adds joints in the same order (MuJoCo bodies are numbered parents-first, depth-first), which
``PinocchioKinematics`` checks at construction.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from retarget._jit import F2, F2C, F3CW, kernel
from retarget.errors import RetargetError


@kernel(F2C, F2C, F2, F3CW)
def _frame_jacobians(J, masks, points, out):
    """Fill ``out`` (k, 3 or 6, nv) with the Jacobians of points ``points`` (k, 3) [m, world]
    fixed to bodies whose dofs are ``masks`` (k, nv), linear rows then (for 6) angular, from
    Pinocchio's world-frame joint Jacobian ``J`` (6, nv): per dof the twist ``(v₀, ω)`` at the
    world origin, so a point ``p`` moves at ``v₀ + ω × p``. One pass instead of the dozen
    NumPy operations it took (Shadow's 31 sites, per solver iterate)."""
    k, rows, nv = out.shape
    for s in range(k):
        px, py, pz = points[s, 0], points[s, 1], points[s, 2]
        for j in range(nv):
            mk = masks[s, j]
            wx, wy, wz = J[3, j], J[4, j], J[5, j]
            out[s, 0, j] = (J[0, j] + (pz * wy - py * wz)) * mk
            out[s, 1, j] = (J[1, j] + (px * wz - pz * wx)) * mk
            out[s, 2, j] = (J[2, j] + (py * wx - px * wy)) * mk
            if rows == 6:
                out[s, 3, j] = wx * mk
                out[s, 4, j] = wy * mk
                out[s, 5, j] = wz * mk


def _se3(R: np.ndarray, p: np.ndarray):
    import pinocchio as pin

    return pin.SE3(np.asarray(R, dtype=np.float64), np.asarray(p, dtype=np.float64))


def _quat_wxyz_to_R(q: np.ndarray) -> np.ndarray:
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(q, dtype=np.float64))
    return R.reshape(3, 3)


@dataclass
class PinocchioKinematics:
    """Pinocchio model + data built from an ``MjModel``, with named MuJoCo sites as frames.

    Attributes:
        model, data: the Pinocchio model and data.
        site_frames: MuJoCo site name → Pinocchio frame id.
        body_frames: MuJoCo body name → Pinocchio frame id (the body's own frame).
        joint_names: MuJoCo joint names in ``qpos`` order.
    """

    mj_model: mujoco.MjModel
    model: object = field(init=False)
    data: object = field(init=False)
    site_frames: dict[str, int] = field(init=False)
    body_frames: dict[str, int] = field(init=False)
    joint_names: list[str] = field(init=False)

    def __post_init__(self) -> None:
        import pinocchio as pin

        m = self.mj_model
        if m.nq != m.nv:
            raise RetargetError(
                "PinocchioKinematics supports hinge and slide joints only (nq == nv); "
                f"this model has nq={m.nq}, nv={m.nv}"
            )
        model = pin.Model()
        model.name = "from_mjmodel"
        # Per MuJoCo body: the Pinocchio joint id that moves it and the placement of the body
        # frame in that joint's frame.
        body_joint = {0: 0}
        body_in_joint = {0: pin.SE3.Identity()}
        body_frames: dict[str, int] = {}
        joint_names: list[str] = []
        for b in range(1, m.nbody):
            parent = int(m.body_parentid[b])
            parent_jid = body_joint[parent]
            X_parent_body = body_in_joint[parent] * _se3(
                _quat_wxyz_to_R(m.body_quat[b]), m.body_pos[b]
            )
            jnt_ids = [j for j in range(m.njnt) if m.jnt_bodyid[j] == b]
            cur_jid = parent_jid
            # Placement of the next joint in the current joint's frame, and the current anchor.
            X_prev = X_parent_body
            anchor_prev = np.zeros(3)
            for j in jnt_ids:
                jtype = int(m.jnt_type[j])
                axis = np.asarray(m.jnt_axis[j], dtype=np.float64)
                anchor = np.asarray(m.jnt_pos[j], dtype=np.float64)
                placement = X_prev * _se3(np.eye(3), anchor - anchor_prev)
                if jtype == mujoco.mjtJoint.mjJNT_HINGE:
                    jm = pin.JointModelRevoluteUnaligned(axis)
                elif jtype == mujoco.mjtJoint.mjJNT_SLIDE:
                    jm = pin.JointModelPrismaticUnaligned(axis)
                else:
                    raise RetargetError(
                        f"joint {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)!r} has an "
                        "unsupported type (free/ball); hands use hinge and slide joints"
                    )
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
                lo, hi = m.jnt_range[j] if m.jnt_limited[j] else (-1e10, 1e10)
                cur_jid = model.addJoint(
                    cur_jid,
                    jm,
                    placement,
                    name,
                    np.full(1, 1e3),
                    np.full(1, 1e3),
                    np.array([lo], dtype=np.float64),
                    np.array([hi], dtype=np.float64),
                )
                joint_names.append(name)
                X_prev = pin.SE3.Identity()
                anchor_prev = anchor
            if jnt_ids:
                X_joint_body = _se3(np.eye(3), -anchor_prev)
            else:
                X_joint_body = X_parent_body
            body_joint[b] = cur_jid
            body_in_joint[b] = X_joint_body
            inertia = pin.Inertia(
                float(m.body_mass[b]),
                np.asarray(m.body_ipos[b], dtype=np.float64),
                _quat_wxyz_to_R(m.body_iquat[b])
                @ np.diag(m.body_inertia[b])
                @ _quat_wxyz_to_R(m.body_iquat[b]).T,
            )
            model.appendBodyToJoint(cur_jid, inertia.se3Action(X_joint_body), pin.SE3.Identity())
            bname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
            body_frames[bname] = model.addFrame(
                pin.Frame(bname, cur_jid, X_joint_body, pin.FrameType.OP_FRAME)
            )
        site_frames: dict[str, int] = {}
        for s in range(m.nsite):
            b = int(m.site_bodyid[s])
            X = body_in_joint[b] * _se3(_quat_wxyz_to_R(m.site_quat[s]), m.site_pos[s])
            sname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s) or f"site{s}"
            site_frames[sname] = model.addFrame(
                pin.Frame(sname, body_joint[b], X, pin.FrameType.OP_FRAME)
            )
        mj_names = [
            mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}" for j in range(m.njnt)
        ]
        if joint_names != mj_names:
            raise RetargetError(
                "MuJoCo joint order is not depth-first; cannot align qpos with Pinocchio"
            )
        self.model = model
        self.data = model.createData()
        self._mj_data = mujoco.MjData(m)  # site poses (see forward)
        self._site_jac: np.ndarray | None = None
        # Which dofs move each frame (the support of its parent joint), for the batched
        # Jacobians computed from the world-frame joint Jacobian ``data.J``.
        dof_mask = np.zeros((model.njoints, model.nv))
        for jid in range(1, model.njoints):
            for s in model.supports[jid]:
                if s > 0:
                    j = model.joints[s]
                    dof_mask[jid, j.idx_v : j.idx_v + j.nv] = 1.0
        self._frame_mask = dof_mask[[f.parentJoint for f in model.frames]]  # (nframes, nv)
        self._ids: dict[tuple[str, ...], np.ndarray] = {}
        self._site_fids = np.array(list(site_frames.values()), dtype=int)  # MuJoCo site order
        self._site_mask = np.ascontiguousarray(self._frame_mask[self._site_fids])
        self._J = np.zeros((6, model.nv))  # data.J in C order (see forward)
        # point_jacobians: body-name tuple → (frame ids, their dof masks (k, 1, nv)).
        self._bodies_memo: dict[tuple[str, ...], tuple[np.ndarray, np.ndarray]] = {}
        self._site_row = {name: i for i, name in enumerate(site_frames)}
        self.site_frames = site_frames
        self.body_frames = body_frames
        self.joint_names = joint_names

    @property
    def nq(self) -> int:
        return self.model.nq

    def forward(self, q: np.ndarray) -> None:
        """Joint placements, frame placements and joint Jacobians at ``q`` (MuJoCo qpos order).

        Jacobians come from Pinocchio's world-frame joint Jacobian ``data.J``; site poses from
        ``mj_kinematics`` on the same ``MjModel`` (equal to Pinocchio's frame placements
        ``data.oMf`` to 1e-10, which tests check, but read as one array: Shadow's 31 sites cost
        37 µs through ``oMf`` and 2 µs this way). The sites' Jacobians are computed all at once
        on first use and shared by every query until the next ``forward``.
        """
        import pinocchio as pin

        q = np.asarray(q, dtype=np.float64)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        # data.J comes column-major from eigenpy; the batched Jacobians broadcast over its
        # rows, ~2× faster in row-major order (Shadow's 31 sites: 23 → 10 µs).
        self._J = np.ascontiguousarray(self.data.J).reshape(6, self.model.nv)
        self._mj_data.qpos[:] = q
        mujoco.mj_kinematics(self.mj_model, self._mj_data)
        self._site_jac = None

    def site_rows(self, sites: tuple[str, ...]) -> np.ndarray:
        """(k,) rows of ``sites`` in :meth:`site_arrays`, memoised per name tuple."""
        rows = self._ids.get(sites)
        if rows is None:
            for s in sites:
                self.frame_id(s)  # raises on an unknown name
            rows = np.array([self._site_row[s] for s in sites], dtype=int)
            self._ids[sites] = rows
        return rows

    def site_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Every site's Jacobian (nsite, 6, nv) and world position (nsite, 3) [m] at the last
        :meth:`forward`, in MuJoCo site order (shared, read-only: copy to modify)."""
        return self._all_site_jacobians(), self._all_site_positions()

    def site_rotation_array(self) -> np.ndarray:
        """(nsite, 9) every site's world rotation matrix, row-major, at the last
        :meth:`forward`, in MuJoCo site order (a view: do not modify)."""
        return self._mj_data.site_xmat

    def _all_site_positions(self) -> np.ndarray:
        """(nsite, 3) [m] every site's world position at the last :meth:`forward` (a view)."""
        return self._mj_data.site_xpos

    def _all_site_jacobians(self) -> np.ndarray:
        """(nsite, 6, nv) every site's Jacobian at the last :meth:`forward`."""
        if self._site_jac is None:
            J = np.empty((self._site_fids.size, 6, self.model.nv))
            _frame_jacobians(self._J, self._site_mask, self._all_site_positions(), J)
            J.flags.writeable = False  # shared until the next forward(): callers must copy
            self._site_jac = J
        return self._site_jac

    def world_jacobian(self) -> np.ndarray:
        """(6, nv) every joint's motion at the last :meth:`forward` as a world-frame twist
        ``(v₀, ω)`` at the world origin (Pinocchio's ``data.J``, row-major; shared, do not
        modify): a point ``p`` fixed to a body moves at ``v₀ + ω × p`` over the dofs of
        :meth:`body_dof_masks`."""
        return self._J

    def body_dof_masks(self, bodies) -> np.ndarray:
        """(k, nv) 1 where a dof moves the body (its support), else 0, per body name."""
        try:
            ids = [self.body_frames[b] for b in bodies]
        except KeyError as e:
            raise RetargetError(f"unknown body {e.args[0]!r}") from None
        return np.ascontiguousarray(self._frame_mask[ids])

    def _point_jacobians(
        self, frame_ids: np.ndarray, p_world: np.ndarray, mask: np.ndarray | None = None
    ) -> np.ndarray:
        """(k, 3, nv) Jacobians of points ``p_world`` (k, 3) fixed to the given frames
        (``mask``: their dof masks ``_frame_mask[frame_ids]``, when the caller has them;
        :func:`_frame_jacobians`)."""
        out = np.empty((p_world.shape[0], 3, self.model.nv))
        _frame_jacobians(
            self._J, self._frame_mask[frame_ids] if mask is None else mask, p_world, out
        )
        return out

    def site_positions(self, sites: tuple[str, ...]) -> np.ndarray:
        """(k, 3) world positions [m] of several sites after :meth:`forward`."""
        return self._all_site_positions()[self.site_rows(tuple(sites))]

    def site_jacobians(self, sites: tuple[str, ...]) -> np.ndarray:
        """(k, 6, nv) Jacobians of several sites (as :meth:`site_jacobian`)."""
        return self._all_site_jacobians()[self.site_rows(tuple(sites))]

    def point_jacobians(self, bodies: tuple[str, ...], p_world: np.ndarray) -> np.ndarray:
        """(k, 3, nv) Jacobians of points (k, 3) [m, world] fixed to ``bodies`` (one each)."""
        bodies = bodies if isinstance(bodies, tuple) else tuple(bodies)
        memo = self._bodies_memo.get(bodies)
        if memo is None:
            try:
                ids = np.array([self.body_frames[b] for b in bodies], dtype=int)
            except KeyError as e:
                raise RetargetError(f"unknown body {e.args[0]!r}") from None
            if len(self._bodies_memo) > 4096:  # (contact sets vary from frame to frame)
                self._bodies_memo.clear()
            memo = self._bodies_memo[bodies] = (
                ids,
                np.ascontiguousarray(self._frame_mask[ids]),
            )
        ids, mask = memo
        p = np.asarray(p_world, dtype=np.float64).reshape(-1, 3)
        return self._point_jacobians(ids, p, mask)

    def frame_id(self, site: str) -> int:
        try:
            return self.site_frames[site]
        except KeyError:
            raise RetargetError(
                f"unknown site {site!r}; model sites: {', '.join(sorted(self.site_frames))}"
            ) from None

    def site_position(self, site: str) -> np.ndarray:
        """(3,) world position [m] of a site after :meth:`forward`."""
        return self._mj_data.site_xpos[self.site_rows((site,))[0]].copy()

    def site_rotation(self, site: str) -> np.ndarray:
        """(3, 3) world rotation of a site after :meth:`forward`."""
        return self._mj_data.site_xmat[self.site_rows((site,))[0]].reshape(3, 3).copy()

    def site_jacobian(self, site: str) -> np.ndarray:
        """(6, nv) Jacobian of a site: linear velocity of its origin and angular velocity, both
        in world axes (Pinocchio ``LOCAL_WORLD_ALIGNED``), after :meth:`forward`."""
        return self._all_site_jacobians()[self.site_rows((site,))[0]]

    def point_jacobian(self, body: str, p_world: np.ndarray) -> np.ndarray:
        """(3, nv) Jacobian of a point rigidly attached to ``body``, given in world coordinates."""
        return self.point_jacobians((body,), p_world)[0]


class MujocoKinematics:
    """The same kinematic queries on MuJoCo itself (the mink backend's view of the model).

    ``forward`` runs ``mj_kinematics`` and ``mj_comPos`` (what the Jacobian functions need) on
    the first ``nq`` entries of ``qpos``; other entries (e.g. a mocap object) are left alone.
    """

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData | None = None, nq: int | None = None
    ):
        self.mj_model = model
        self.data = data if data is not None else mujoco.MjData(model)
        self._nq = model.nq if nq is None else nq
        self._site_ids: dict[str, int] = {}
        self._body_ids: dict[str, int] = {}

    @property
    def nq(self) -> int:
        return self._nq

    def forward(self, q: np.ndarray) -> None:
        self.data.qpos[: self._nq] = q
        mujoco.mj_kinematics(self.mj_model, self.data)
        mujoco.mj_comPos(self.mj_model, self.data)

    def _site(self, site: str) -> int:
        sid = self._site_ids.get(site)
        if sid is None:
            sid = mujoco.mj_name2id(self.mj_model, mujoco.mjtObj.mjOBJ_SITE, site)
            if sid < 0:
                raise RetargetError(f"unknown site {site!r}")
            self._site_ids[site] = sid
        return sid

    def site_position(self, site: str) -> np.ndarray:
        return self.data.site_xpos[self._site(site)].copy()

    def site_rotation(self, site: str) -> np.ndarray:
        return self.data.site_xmat[self._site(site)].reshape(3, 3).copy()

    def site_jacobian(self, site: str) -> np.ndarray:
        J = np.zeros((6, self.mj_model.nv))
        mujoco.mj_jacSite(self.mj_model, self.data, J[:3], J[3:], self._site(site))
        return J[:, : self._nq]

    def site_positions(self, sites: tuple[str, ...]) -> np.ndarray:
        return self.data.site_xpos[[self._site(s) for s in sites]].reshape(-1, 3)

    def site_jacobians(self, sites: tuple[str, ...]) -> np.ndarray:
        return np.stack([self.site_jacobian(s) for s in sites]).reshape(-1, 6, self._nq)

    def point_jacobians(self, bodies: tuple[str, ...], p_world: np.ndarray) -> np.ndarray:
        p = np.asarray(p_world, dtype=np.float64).reshape(-1, 3)
        return np.stack(
            [self.point_jacobian(b, x) for b, x in zip(bodies, p, strict=True)]
        ).reshape(-1, 3, self._nq)

    def point_jacobian(self, body: str, p_world: np.ndarray) -> np.ndarray:
        bid = self._body_ids.get(body)
        if bid is None:
            bid = mujoco.mj_name2id(self.mj_model, mujoco.mjtObj.mjOBJ_BODY, body)
            if bid < 0:
                raise RetargetError(f"unknown body {body!r}")
            self._body_ids[body] = bid
        jp = np.zeros((3, self.mj_model.nv))
        mujoco.mj_jac(self.mj_model, self.data, jp, None, np.asarray(p_world, np.float64), bid)
        return jp[:, : self._nq]
