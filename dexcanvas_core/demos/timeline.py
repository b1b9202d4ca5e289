"""Key-framed hand and object timelines for the demonstration scripts: minimum-jerk segments
between key states (:class:`State`), finger posture keys interpolated at bounded joint speed,
and :class:`Timeline`, which samples them at the data rate ``FPS``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from dexcanvas_core.mano.hand_model import N_DOF, dof_index, rodrigues
from dexcanvas_core.rotations import matrix_to_aa

FPS = 120
"""Frame rate of generated demonstrations [Hz]."""


def min_jerk(tau: np.ndarray | float) -> np.ndarray | float:
    """Minimum-jerk position profile on ``[0, 1]`` (zero velocity and acceleration at ends)."""
    t = np.clip(tau, 0.0, 1.0)
    return t**3 * (10.0 - 15.0 * t + 6.0 * t * t)


@dataclass
class State:
    """Everything a frame holds: wrist (J0) pose, driven finger angles, object pose (world)."""

    R_w: np.ndarray
    p_w: np.ndarray
    q: np.ndarray
    R_o: np.ndarray
    p_o: np.ndarray

    def copy(self) -> State:
        return State(
            self.R_w.copy(), self.p_w.copy(), self.q.copy(), self.R_o.copy(), self.p_o.copy()
        )

    @property
    def T_wrist_obj(self) -> tuple[np.ndarray, np.ndarray]:
        """Object pose in the wrist frame ``(R, p)``."""
        return self.R_w.T @ self.R_o, self.R_w.T @ (self.p_o - self.p_w)


def key_grid(keys: np.ndarray) -> np.ndarray:
    """Progress value of each key posture ``(K, 22)``, proportional to the joint-space path
    length so far (so no stretch between keys moves the fingers faster than the others)."""
    step = np.abs(np.diff(keys, axis=0)).max(axis=1)
    total = float(step.sum())
    if total < 1e-9:
        return np.linspace(0.0, 1.0, len(keys))
    return np.concatenate([[0.0], np.cumsum(step) / total])


def interp_keys(s: float, grid: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Posture at progress ``s``: piecewise linear through ``keys`` placed at ``grid``."""
    k = int(np.clip(np.searchsorted(grid, s, side="right") - 1, 0, len(grid) - 2))
    span = grid[k + 1] - grid[k]
    u = 0.0 if span <= 0 else (s - grid[k]) / span
    return keys[k] + min(max(u, 0.0), 1.0) * (keys[k + 1] - keys[k])


MAX_FINGER_SPEED = 4.0
"""Peak finger-joint speed [rad/s] a scripted phase is slowed down to (checks allow 10)."""


def keyed_duration(seconds: float, grid: np.ndarray, keys: np.ndarray) -> float:
    """A phase duration long enough that fingers passing through ``keys`` at progress ``grid``
    stay under ``MAX_FINGER_SPEED`` (the minimum-jerk progress peaks at 1.875 / duration)."""
    step = np.abs(np.diff(keys, axis=0)).max(axis=1)
    span = np.maximum(np.diff(grid), 1e-9)
    return max(seconds, 1.875 * float((step / span).max(initial=0.0)) / MAX_FINGER_SPEED)


def _relative_rotvec(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    """Rotation vector ``ω`` (world frame) with ``exp(ω) R0 = R1``."""
    return matrix_to_aa(R1 @ R0.T)


@dataclass
class Timeline:
    """Frames of a demonstration under construction, with its contact and motion bookkeeping.

    ``contacts`` maps a contact part (capsule name or ``"palm"``) to ``[start, end]`` frame
    intervals (inclusive) during which the script holds that part on the object; ``moves`` are
    the frame intervals during which the object moves.
    """

    states: list[State]
    fps: int = FPS
    contacts: dict[str, list[list[int]]] = field(default_factory=dict)
    moves: list[list[int]] = field(default_factory=list)
    phases: list[tuple[str, int, int]] = field(default_factory=list)
    notes: dict[str, float] = field(default_factory=dict)
    """What the script did, in numbers (e.g. ``rotation_deg``, ``roll_mm``)."""

    @property
    def frame(self) -> int:
        """Index of the last frame."""
        return len(self.states) - 1

    @property
    def now(self) -> State:
        return self.states[-1]

    def phase(self, name: str, seconds: float, fn: Callable[[float], State]) -> None:
        """Append ``round(seconds · fps)`` frames ``fn(s)``, ``s`` the minimum-jerk progress."""
        n = max(1, round(seconds * self.fps))
        start = self.frame
        for i in range(1, n + 1):
            self.states.append(fn(float(min_jerk(i / n))))
        self.phases.append((name, start, self.frame))

    def hold(self, name: str, seconds: float) -> None:
        s = self.now
        self.phase(name, seconds, lambda _: s.copy())

    def contact_on(self, parts) -> None:
        for p in parts:
            self.contacts.setdefault(p, []).append([self.frame, -1])

    def contact_off(self, parts) -> None:
        for p in parts:
            self.contacts[p][-1][1] = self.frame

    def contact_off_all(self) -> None:
        for intervals in self.contacts.values():
            if intervals and intervals[-1][1] < 0:
                intervals[-1][1] = self.frame

    # -- phase builders ----------------------------------------------------------------------

    def move_hand(
        self,
        name: str,
        seconds: float,
        *,
        R_w: np.ndarray | None = None,
        p_w: np.ndarray | None = None,
        q: np.ndarray | None = None,
        carry: bool = False,
    ) -> None:
        """Wrist and fingers to a target (slerp / lerp); the object stays or, with ``carry``,
        moves rigidly with the wrist."""
        a = self.now.copy()
        R1 = a.R_w if R_w is None else R_w
        p1 = a.p_w if p_w is None else p_w
        q1 = a.q if q is None else q
        w = _relative_rotvec(a.R_w, R1)
        R_wo, p_wo = a.T_wrist_obj

        def fn(s: float) -> State:
            R = rodrigues(w * s) @ a.R_w
            p = a.p_w + s * (p1 - a.p_w)
            st = State(R, p, a.q + s * (q1 - a.q), a.R_o, a.p_o)
            if carry:
                st.R_o = R @ R_wo
                st.p_o = R @ p_wo + p
            return st

        self._moving(carry, lambda: self.phase(name, seconds, fn))

    def move_object(
        self,
        name: str,
        seconds: float,
        R_o: np.ndarray,
        p_o: np.ndarray,
        q: np.ndarray | None = None,
    ) -> None:
        """Object to a target pose (rotation about its centre), the hand carrying it rigidly;
        fingers optionally to ``q`` (re-solved in-hand grasps)."""
        a = self.now.copy()
        w = _relative_rotvec(a.R_o, R_o)
        R_ow = a.R_o.T @ a.R_w
        p_ow = a.R_o.T @ (a.p_w - a.p_o)
        q1 = a.q if q is None else q

        def fn(s: float) -> State:
            Ro = rodrigues(w * s) @ a.R_o
            po = a.p_o + s * (p_o - a.p_o)
            return State(Ro @ R_ow, Ro @ p_ow + po, a.q + s * (q1 - a.q), Ro, po)

        self._moving(True, lambda: self.phase(name, seconds, fn))

    def move_fingers(self, name: str, seconds: float, q_keys: list[np.ndarray]) -> None:
        """Fingers through key postures (piecewise linear along the joint-space path, timed by
        the minimum-jerk progress), the wrist and the object still. The phase lasts at least
        ``seconds``, longer if the fingers would exceed ``MAX_FINGER_SPEED``."""
        a = self.now.copy()
        keys = np.stack([a.q, *q_keys])
        grid = key_grid(keys)
        seconds = keyed_duration(seconds, grid, keys)

        def fn(s: float) -> State:
            return State(a.R_w, a.p_w, interp_keys(s, grid, keys), a.R_o, a.p_o)

        self.phase(name, seconds, fn)

    def turn(
        self,
        name: str,
        seconds: float,
        axis: np.ndarray,
        angle_obj: float,
        angle_wrist: float,
        grid: np.ndarray | None = None,
        keys: np.ndarray | None = None,
        pivot: np.ndarray | None = None,
    ) -> None:
        """Object and wrist turn about ``axis`` (world) through ``pivot`` (default: the
        object's centre) by their own angles [rad]; the fingers keep their angles or pass
        through the postures ``keys`` at turn progress ``grid`` (``keys[0]`` = the current
        posture)."""
        a = self.now.copy()
        axis = axis / np.linalg.norm(axis)
        c = a.p_o if pivot is None else np.asarray(pivot, float)
        if keys is None:
            grid, keys = np.array([0.0, 1.0]), np.stack([a.q, a.q])
        seconds = keyed_duration(seconds, grid, keys)

        def fn(s: float) -> State:
            Rw = rodrigues(axis * angle_wrist * s)
            Ro = rodrigues(axis * angle_obj * s)
            q = interp_keys(s, grid, keys)
            return State(Rw @ a.R_w, Rw @ (a.p_w - c) + c, q, Ro @ a.R_o, Ro @ (a.p_o - c) + c)

        self._moving(True, lambda: self.phase(name, seconds, fn))

    def roll(self, name: str, seconds: float, displacement: np.ndarray, radius: float) -> None:
        """Roll the object on the table by a horizontal ``displacement`` [m] without slip: it
        turns by ``|d| / radius`` about ``z × d``; the hand translates with its centre."""
        a = self.now.copy()
        d = np.asarray(displacement, float)
        axis = np.cross([0.0, 0.0, 1.0], d)
        axis /= np.linalg.norm(axis)
        angle = np.linalg.norm(d) / radius

        def fn(s: float) -> State:
            return State(
                a.R_w, a.p_w + s * d, a.q.copy(), rodrigues(axis * angle * s) @ a.R_o, a.p_o + s * d
            )

        self._moving(True, lambda: self.phase(name, seconds, fn))

    def _moving(self, moves: bool, run: Callable[[], None]) -> None:
        start = self.frame
        run()
        if moves:
            if self.moves and self.moves[-1][1] == start:
                self.moves[-1][1] = self.frame
            else:
                self.moves.append([start, self.frame])

    # -- output ------------------------------------------------------------------------------

    def arrays(self) -> dict[str, np.ndarray]:
        """Stacked per-frame arrays: ``R_w (T, 3, 3)``, ``p_w (T, 3)``, ``q (T, 22)``, ``R_o``,
        ``p_o``."""
        return {
            "R_w": np.stack([s.R_w for s in self.states]),
            "p_w": np.stack([s.p_w for s in self.states]),
            "q": np.stack([s.q for s in self.states]),
            "R_o": np.stack([s.R_o for s in self.states]),
            "p_o": np.stack([s.p_o for s in self.states]),
        }


def relaxed_posture() -> np.ndarray:
    """``(22,)`` a relaxed open hand (start and end of every demonstration)."""
    q = np.zeros(N_DOF)
    for f, k in (("index", 0.8), ("middle", 0.9), ("ring", 1.0), ("pinky", 1.1)):
        q[dof_index(f"{f}1_flex")] = 0.25 * k
        q[dof_index(f"{f}2_flex")] = 0.35 * k
        q[dof_index(f"{f}3_flex")] = 0.15 * k
    q[dof_index("thumb1_flex")] = 0.2
    q[dof_index("thumb1_abd")] = -0.1
    q[dof_index("thumb2_flex")] = 0.15
    q[dof_index("thumb3_flex")] = 0.15
    return q
