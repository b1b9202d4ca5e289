import numpy as np
import pytest

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano import HandSkeleton
from dexcanvas_core.rotations import aa_to_matrix, rotation_angle_between_aa
from dexcanvas_core.trajectory import (
    CONTACT_PAIR_FIELDS,
    CONTACT_TOTAL_FIELDS,
    Contacts,
    HandTrack,
    ObjectMove,
    ObjectTrack,
    Trajectory,
)


def make_traj(T=121, fps=120.0, seed=0, contacts=True) -> Trajectory:
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fps
    # Smooth motion: a rotation about a fixed axis at constant rate, a linear wrist path.
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    rot = axis * (0.2 + 0.5 * t)[:, None]
    pose = np.zeros((T, 48))
    pose[:, 3:] = 0.3 * np.sin(t[:, None] + np.arange(45))
    wrist = np.stack([0.1 * t, 0.0 * t, 0.2 + 0.05 * t], 1)
    # A hand-sized skeleton (the plausibility checks refuse other scales), 1 mm of noise.
    keypoints = HandSkeleton.default("right").rest_keypoints + wrist[:, None]
    hand = HandTrack(
        name="right",
        global_pos=wrist,
        global_rot_aa=rot,
        hand_pose=pose,
        joint_pos=keypoints + 1e-3 * rng.normal(size=(T, 21, 3)),
        urdf_dof=rng.normal(size=(T, 26)),
    )
    obj = ObjectTrack("cube2", np.stack([0.2 * t, t * 0, t * 0 + 0.03], 1), -rot)
    c = None
    if contacts:
        frames = np.repeat(np.arange(T), 2)
        K = frames.size
        c = Contacts(
            num_frames=T,
            frame=frames,
            hand_name=["right"] * K,
            joint_name=["thumb_ip", "index_dip"] * T,
            object_name=["cube2"] * K,
            totals={k: np.tile([[1.0, 0, 0]], (K, 1)) * (1 + np.arange(K))[:, None]
                    for k in CONTACT_TOTAL_FIELDS},
            pair_offsets=np.arange(K + 1),
            pairs={k: rng.normal(size=(K, 3)) for k in CONTACT_PAIR_FIELDS},
        )  # fmt: skip
    return Trajectory(
        uuid="t0",
        timestamp=t,
        fps=fps,
        hands=[hand],
        objects=[obj],
        gesture="tripod",
        scene="cube2",
        object_move=[ObjectMove("cube2", T // 4, 3 * T // 4 - 1)],
        contacts=c,
    )


def test_validate_accepts_good_trajectory():
    assert make_traj().validate().num_frames == 121


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda t: t.timestamp.__setitem__(10, t.timestamp[9]), "strictly increasing; frame 10"),
        (lambda t: setattr(t, "fps", 100.0), "data_fps is 100 Hz but the timestamps run at 120"),
        (lambda t: t.hand.global_pos.__setitem__((5, 1), np.nan), r"mano_global_pos contains NaN"),
        (lambda t: t.object.rot_aa.__setitem__(3, [0, 0, 90.0]), "exceeds 6.283 rad"),
        (lambda t: t.hand.hand_pose.__setitem__((0, 4), 4.0), r"finger joints.*exceeds 3.142"),
        (lambda t: setattr(t, "object_move", [ObjectMove("cube2", 100, 500)]), "outside frames"),
        (
            lambda t: setattr(t.object, "pos", t.object.pos[:-1]),
            "objects.cube2..pos has 120 frames",
        ),
    ],
)
def test_validate_names_the_problem(mutate, message):
    t = make_traj()
    mutate(t)
    with pytest.raises(ValidationError, match=message):
        t.validate()


def test_constructor_checks_shapes():
    with pytest.raises(
        ValidationError, match=r"mano_hand_pose must have shape \(10, 48\), got \(10, 45\)"
    ):
        HandTrack("right", np.zeros((10, 3)), np.zeros((10, 3)), np.zeros((10, 45)))
    with pytest.raises(ValidationError, match="26 or 28 columns, got 20"):
        HandTrack("right", np.zeros((10, 3)), np.zeros((10, 3)), np.zeros((10, 48)),
                  urdf_dof=np.zeros((10, 20)))  # fmt: skip


def test_active_slice_and_contacts_follow():
    t = make_traj()
    a = t.active()
    assert a.num_frames == 60
    assert a.object_move[0].start_frame == 0 and a.object_move[0].end_frame == 59
    np.testing.assert_array_equal(a.hand.hand_pose, t.hand.hand_pose[30:90])
    assert a.contacts.num_records == 120
    np.testing.assert_array_equal(a.contacts.finger_totals(), t.contacts.finger_totals()[30:90])
    a.validate()


def test_crop_starts_a_third_of_the_window_before_the_motion():
    t = make_traj()  # 121 frames, the object moves over frames 30..89
    c = t.crop(30)
    assert c.num_frames == 30 and c.object_move[0].start_frame == 10  # 30 - 30 // 3 = frame 20
    np.testing.assert_array_equal(c.hand.hand_pose, t.hand.hand_pose[20:50])
    assert t.crop(None) is t and t.crop(121) is t
    assert t.crop(110).num_frames == 110 and t.crop(110).hand.hand_pose[0].tolist() == (
        t.hand.hand_pose[0].tolist()
    )  # 30 - 36 < 0: clipped to the first frame


def test_resample_hits_samples_and_interpolates_rotations():
    t = make_traj()
    r = t.resample(60.0)
    assert r.fps == 60.0 and r.num_frames == 61
    r.validate()
    # Every second 120 Hz sample is a 60 Hz sample: values agree exactly there.
    np.testing.assert_allclose(r.hand.global_pos, t.hand.global_pos[::2], atol=1e-6)
    np.testing.assert_allclose(r.hand.hand_pose, t.hand.hand_pose[::2], atol=1e-5)
    # Upsampling a constant-rate rotation gives the constant-rate rotation in between.
    u = t.resample(240.0)
    mid = u.hand.global_rot_aa[1]  # t = 1/240 s
    want = t.hand.global_rot_aa[0] + 0.5 * (t.hand.global_rot_aa[1] - t.hand.global_rot_aa[0])
    assert rotation_angle_between_aa(mid, want) < 1e-6
    assert np.allclose(aa_to_matrix(u.object.rot_aa[::2]), aa_to_matrix(t.object.rot_aa), atol=1e-5)
    assert u.contacts.num_frames == u.num_frames
    assert u.object_move[0].start_frame == 60 and u.object_move[0].end_frame == 178


def test_dense_contacts_and_finger_totals():
    t = make_traj(T=5)
    d = t.contacts.dense()
    assert d["pos_world"].shape == (5, 2, 3) and d["valid"].all()
    tot = t.contacts.finger_totals()
    # Record k carries force (k+1, 0, 0); thumb records are the even ones.
    np.testing.assert_allclose(tot[:, 0, 0], 1 + 2 * np.arange(5))
    np.testing.assert_allclose(tot[:, 1, 0], 2 + 2 * np.arange(5))
    np.testing.assert_allclose(tot[:, 2:], 0)


def test_bad_contact_part_is_named():
    t = make_traj(T=3)
    t.contacts.joint_name[0] = "elbow"
    with pytest.raises(ValidationError, match=r"unknown contact parts \['elbow'\]"):
        t.validate()
