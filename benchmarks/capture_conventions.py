"""Checks of the dataset conventions the ``dexcanvas import`` readers rely on, on local copies.

The datasets are licence-restricted and never part of this repository; point this script at your
copies. It prints the numbers quoted in ``dexcanvas_core/capture/formats/*.py``:

* ``--ho3d DIR`` (HO-3D-style ``meta/`` sequences, e.g. DexYCB exported to that layout) with
  ``--models-dir`` (YCB models): pose space of ``handPose`` (axis-angle vs PCA), what
  ``handTrans`` is, the joint order of ``handJoints3D``, the object rotation as stored vs with the
  exporter's quaternion swap undone (agreement of the resting planes of one camera setup), and
  the up direction the reader's estimate gives (angle to the mean lift, table plane at the
  first frame, hand below the table).
* ``--taco DIR`` (GeneOH-Diffusion's TACO clips): side, ``flat_hand_mean``, what ``hand_trans``
  is, ``obj_verts`` against ``obj_pose`` and the ``.obj``, and the up axis.

    python -m benchmarks.capture_conventions --ho3d DIR --models-dir DIR [--taco DIR]
"""

from __future__ import annotations

import argparse
import logging
from collections import Counter
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from dexcanvas_core.capture.formats._common import UpInput, read_mesh, ups_for
from dexcanvas_core.capture.formats.ho3d import _read_sequence, _sequence_dirs
from dexcanvas_core.capture.up import consensus_up, estimate_up
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS, convert_keypoints
from dexcanvas_core.mano import MANO_TIP_VERTEX_IDS, ManoLayer, axis_angle_to_matrix
from dexcanvas_core.rotations import quat_wxyz_to_matrix
from dexcanvas_core.safe_pickle import load_pickle


def mm(x: float) -> str:
    return f"{x * 1000:.1f} mm"


def stats(x, unit: str = "", scale: float = 1.0) -> str:
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)] * scale
    return (
        f"median {np.median(x):.1f}{unit}, 90% {np.percentile(x, 90):.1f}{unit}, "
        f"max {x.max():.1f}{unit} (n={len(x)})"
    )


def check_ho3d(root: Path, models_dir: Path, every: int) -> None:
    seqs = [_read_sequence(d, "auto", models_dir) for d in _sequence_dirs(root)]
    print(f"\n== {root}: {len(seqs)} sequences, layouts {Counter(s.layout for s in seqs)}")
    layers = {f: ManoLayer(side=seqs[0].side, flat_hand_mean=f) for f in (True, False)}
    err = {k: [] for k in ("aa", "aa_mcp", "aa_tips", "op21", "wrist_J0t", "wrist_t")}
    rest = {True: [], False: []}
    for s in seqs[::every]:
        ok = s.hand_ok
        P, t, J = s.pose48[ok], s.trans[ok], s.joints[ok]
        out = layers[False].forward_numpy(betas=s.betas, hand_pose=P, transl=t)
        d = np.linalg.norm(out.keypoints - J, axis=-1)
        err["aa"].append(d.mean())
        err["aa_mcp"].append(d[:, [1, 4, 7, 10, 13]].mean())
        err["aa_tips"].append(d[:, 16:].mean())
        op = convert_keypoints(out.keypoints, "mano21", "openpose21")
        err["op21"].append(np.linalg.norm(op - J, axis=-1).mean())
        err["wrist_J0t"].append(np.linalg.norm(out.joints[:, 0] - J[:, 0], axis=-1).mean())
        err["wrist_t"].append(np.linalg.norm(t - J[:, 0], axis=-1).mean())
        if (~ok).any() and s.layout == "dexycb-export":  # zero pose frames: joints at rest
            blank = int(np.flatnonzero(~ok)[0])
            z = np.asarray(load_pickle(s.folder / "meta" / f"{blank:04d}.pkl")["handJoints3D"])
            for f in (True, False):
                r = layers[f].forward_numpy(betas=s.betas, hand_pose=np.zeros((1, 48)))
                rest[f].append(np.linalg.norm(r.keypoints[0] - z, axis=-1).mean())
    print("handPose[3:] read as axis-angle (flat_hand_mean=False), keypoints vs handJoints3D:")
    print(
        f"  all {mm(np.mean(err['aa']))}, MCP joints {mm(np.mean(err['aa_mcp']))}, "
        f"fingertips {mm(np.mean(err['aa_tips']))}; OpenPose order {mm(np.mean(err['op21']))}"
    )
    if rest[True]:
        print(
            f"  zero-pose frames: mean pose {mm(np.mean(rest[False]))}, "
            f"flat hand {mm(np.mean(rest[True]))}"
        )
    spread = np.concatenate([s.pose48[s.hand_ok, 3:] for s in seqs[::every]]).std(axis=0)
    print(
        f"  spread of handPose[3:] by dimension: first 6 {np.round(spread[:6], 2).tolist()}, "
        f"last 6 {np.round(spread[-6:], 2).tolist()} rad"
    )
    print(
        f"handTrans: wrist = J0 + handTrans {mm(np.mean(err['wrist_J0t']))}, "
        f"wrist = handTrans {mm(np.mean(err['wrist_t']))}"
    )

    if any(s.layout == "dexycb-export" for s in seqs):
        print("objRot of the DexYCB export, resting planes per camera setup (folder):")
        for label, fix in (("as stored", False), ("swap undone", True)):
            devs = []
            for group in sorted({s.folder.parent for s in seqs}):
                ups = []
                for s in (s for s in seqs if s.folder.parent == group):
                    q = s.obj_quat
                    if not fix:  # the stored rotation vector, taken at face value
                        stored = Rotation.from_quat(q, scalar_first=True).as_quat()
                        rv = _exporter_rotvec(stored)
                        q = Rotation.from_rotvec(rv).as_quat(scalar_first=True)
                    try:
                        ups.append(estimate_up(s.vertices, s.obj_pos, q).up)
                    except ValidationError:
                        ups.append(None)
                try:
                    devs += consensus_up(ups, min_share=0.0).angles_deg.tolist()
                except ValidationError:
                    devs += [np.nan] * len(ups)
            print(
                f"  {label}: angle of each sequence's estimate to its group's consensus "
                f"{stats(devs, '°')}"
            )

    inputs = []
    for s in seqs:
        k = np.flatnonzero(s.obj_ok)
        inputs.append(
            UpInput(str(s.folder), s.vertices, s.obj_pos[k], s.obj_quat[k], str(s.folder.parent))
        )
    for shared in (False, True):
        lift, first, below, hand = [], [], [], []
        try:
            ups = ups_for(inputs, up=None, shared=shared)
        except ValidationError as exc:
            print(f"up ({'shared' if shared else 'per sequence'}): {exc}")
            continue
        for s, (u, h, _) in zip(seqs, ups, strict=True):
            R = quat_wxyz_to_matrix(s.obj_quat)
            X = np.einsum("tij,vj->tvi", R, s.vertices) + s.obj_pos[:, None]
            c = X.mean(1) - X[0].mean(0)
            dist = np.linalg.norm(c, axis=1)
            if dist.max() > 0.02:
                sel = dist >= max(0.02, 0.5 * dist.max())
                L = (c[sel] / dist[sel, None]).mean(0)
                lift.append(np.degrees(np.arccos(np.clip(L @ u / np.linalg.norm(L), -1, 1))))
            first.append((X[0] @ u).min() - h)
            below.append(h - (X @ u).min())
            hand.append(h - (s.joints[s.hand_ok] @ u).min())
        print(f"up ({'shared per folder' if shared else 'per sequence'}):")
        print(f"  angle(up, mean lift) {stats(lift, '°')}")
        print(
            "  object's lowest point - table at the first frame "
            f"{stats(np.abs(first), ' mm', 1000)}; "
            f"> 1 cm above: {int((np.array(first) > 0.01).sum())}"
        )
        print(f"  object below the table (worst frame) {stats(below, ' mm', 1000)}")
        print(
            f"  hand keypoints below the table (worst frame) {stats(hand, ' mm', 1000)}; "
            f"> 2 cm: {int((np.array(hand) > 0.02).sum())}, "
            f"> 5 cm: {int((np.array(hand) > 0.05).sum())}"
        )


def _exporter_rotvec(quat_xyzw: np.ndarray) -> np.ndarray:
    """The exporter's rotation vector of a DexYCB quaternion (x, y, z, w) read as (w, x, y, z)."""
    e0, e = quat_xyzw[:, 0], quat_xyzw[:, 1:]
    n = np.linalg.norm(e, axis=1)
    return e / n[:, None] * (2 * np.arctan(n / e0))[:, None]


def check_taco(root: Path) -> None:
    files = sorted(root.rglob("*.pkl")) if root.is_dir() else [root]
    for f in files:
        d = load_pickle(f, what="TACO clip")
        P = np.asarray(d["hand_pose"], float)
        t = np.asarray(d["hand_trans"], float)
        hv = np.asarray(d["hand_verts"], float)
        tips = hv[:, [MANO_TIP_VERTEX_IDS[k] for k in FINGERS]]
        print(f"\n== {f.name}: {len(P)} frames")
        for side in ("left", "right"):
            for flat in (True, False):
                o = ManoLayer(side=side, flat_hand_mean=flat).forward_numpy(hand_pose=P)
                w = np.linalg.norm(
                    o.keypoints[:, 16:] - o.joints[:, :1] + t[:, None] - tips, axis=-1
                )
                j = np.linalg.norm(o.keypoints[:, 16:] + t[:, None] - tips, axis=-1)
                print(
                    f"  {side:5s} flat_hand_mean={flat!s:5s}: tips vs hand_verts "
                    f"wrist = hand_trans {mm(w.mean())}, wrist = J0 + hand_trans {mm(j.mean())}"
                )
        faces = np.asarray(d["hand_faces"])
        edges = Counter(
            tuple(sorted(e))
            for fc in faces
            for e in ((fc[0], fc[1]), (fc[1], fc[2]), (fc[2], fc[0]))
        )
        hole = sorted({v for e, n in edges.items() if n == 1 for v in e})
        R = axis_angle_to_matrix(torch.tensor(P[:, :3])).numpy()
        local = np.einsum("tji,tj->ti", R, hv[:, hole].mean(1) - t)
        print(
            f"  wrist opening ({len(hole)} boundary vertices) in the hand frame relative to "
            f"hand_trans: {np.round(local.mean(0) * 1000, 1).tolist()} mm, "
            f"std {local.std(0).max() * 1000:.2f} mm"
        )
        pose = np.asarray(d["obj_pose"], float)
        obj = f.with_suffix(".obj")
        if obj.is_file():
            V, _ = read_mesh(obj)
            ov = np.asarray(d["obj_verts"], float)
            if len(V) == ov.shape[1]:
                dev = np.abs(
                    np.einsum("tij,vj->tvi", pose[:, :3, :3], V) + pose[:, None, :3, 3] - ov
                )
                print(f"  obj_verts vs obj_pose · {obj.name}: max {dev.max() * 1000:.4f} mm")
            q = Rotation.from_matrix(pose[:, :3, :3]).as_quat(scalar_first=True)
            e = estimate_up(V, pose[:, :3, 3], q)
            print(
                f"  estimated up {np.round(e.up, 3).tolist()}: "
                f"{np.degrees(np.arccos(e.up[2])):.1f}° from +z; {e.reason}"
            )
        ovz = np.asarray(d["obj_verts"], float)[..., 2].min(axis=1)
        print(
            f"  object's lowest z first/last frame {ovz[0]:.4f} / {ovz[-1]:.4f} m; "
            f"hand's lowest z {hv[..., 2].min():.4f} m"
        )


def main() -> None:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.capture_conventions", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--ho3d", type=Path, help="HO-3D-style sequences (folder)")
    ap.add_argument("--models-dir", type=Path, help="YCB object models")
    ap.add_argument("--every", type=int, default=25, help="hand checks on every n-th sequence")
    ap.add_argument("--taco", type=Path, help="TACO clips (GeneOH-Diffusion release)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    if args.ho3d:
        check_ho3d(args.ho3d, args.models_dir, args.every)
    if args.taco:
        check_taco(args.taco)


if __name__ == "__main__":
    main()
