"""Library misuse: the public functions and configs refuse wrong types, shapes and NaN with the
package's error, one line naming the argument, the value and what was expected."""

from pathlib import Path

import numpy as np
import pytest

from dexcanvas_core import (
    DexCanvasDataset,
    Trajectory,
    builtin_demonstration_path,
    hand_model,
    load_demonstration,
    make_dataloader,
)
from dexcanvas_core.builtin import rebuild_builtin
from dexcanvas_core.checks import check_array, check_float, check_int, check_str_seq
from dexcanvas_core.cli import ExampleConfig, ExportConfig, InfoConfig
from dexcanvas_core.errors import DexCanvasError, ValidationError
from dexcanvas_core.io import build_filter, open_dataset
from retarget import (
    ForceCalibrationConfig,
    RefineConfig,
    RetargetConfig,
    Retargeter,
    RunConfig,
    ValidateConfig,
    get_hand,
    refine_lost,
    retarget_demonstration,
    retarget_keypoints,
    run_metrics,
    run_pipeline,
    run_retarget,
    write_run,
)
from retarget.errors import RetargetError
from retarget.keypoint_input import KeypointsConfig, keypoints_to_trajectory

KP = np.zeros((4, 21, 3))

DEXCANVAS_CASES = [
    # (call, argument named, text of the message)
    (lambda: build_filter(objects="cube2"), "objects", "['cube2']"),
    (lambda: build_filter(operators="op0"), "operators", "['op0']"),
    (lambda: build_filter(manipulation_types=3), "manipulation_types", "3 (int)"),
    (lambda: build_filter(objects=["cube2", None]), "objects[1]", "None"),
    (lambda: build_filter(extra=["a = 1"]), "extra", "list"),
    (lambda: open_dataset(3), "path", "3 (int)"),
    (lambda: open_dataset(None), "path", "None"),
    (lambda: Trajectory("x", np.zeros(3), "120", [], []), "fps", "'120' (str)"),
    (lambda: DexCanvasDataset(3), "path", "3 (int)"),
    (lambda: DexCanvasDataset(fps="120"), "fps", "'120' (str)"),
    (lambda: DexCanvasDataset(max_frames=2.5), "max_frames", "2.5"),
    (lambda: DexCanvasDataset(active_only="yes"), "active_only", "'yes'"),
    (lambda: load_demonstration("cube2/tripod", index="0"), "index", "'0' (str)"),
    (lambda: load_demonstration("cube2/tripod", index=-1), "index", ">= 0"),
    (lambda: load_demonstration("cube2/tripod", dataset=1.5), "dataset", "1.5"),
    (lambda: load_demonstration(["cube2/tripod"]), "pair", "list"),
    (lambda: rebuild_builtin(pairs="cube2/tripod"), "pairs", "['cube2/tripod']"),
    (lambda: InfoConfig(None), "path", "None"),
    (lambda: ExportConfig("a.lance", "b.parquet", objects="cube2"), "objects", "['cube2']"),
    (lambda: ExampleConfig("ex.lance", seed="1"), "seed", "'1' (str)"),
    (lambda: hand_model("1.1"), "scale", "'1.1' (str)"),
    (lambda: make_dataloader("ex.lance"), "dataset", "DexCanvasDataset(path)"),
    (lambda: make_dataloader([1, 2], batch_size="4"), "batch_size", "'4' (str)"),
    (lambda: make_dataloader([1, 2], num_workers=-1), "num_workers", ">= 0"),
    (lambda: builtin_demonstration_path(["cube2/tripod"]), "pair", "list"),
]

RETARGET_CASES = [
    (lambda: RunConfig(hand="shadow", index="0"), "index", "'0' (str)"),
    (lambda: RunConfig(hand="shadow", index=-2), "index", ">= 0"),
    (lambda: RunConfig(hand=3), "hand", "3 (int)"),
    (lambda: RunConfig(hand="shadow", pair=["cube2/tripod"]), "pair", "list"),
    (lambda: RunConfig(hand="shadow", dataset=1), "dataset", "1 (int)"),
    (lambda: RunConfig(hand="shadow", backend="pinochio"), "backend", "'pinocchio'"),
    (lambda: RunConfig(hand="shadow", forces="yes"), "forces", "'yes'"),
    (lambda: RunConfig(hand="shadow", force_scale=float("nan")), "force_scale", "nan"),
    (lambda: RunConfig(hand="shadow", force_scale="2"), "force_scale", "'2' (str)"),
    (lambda: RunConfig(hand="shadow", refine_retries=1.5), "refine_retries", "1.5"),
    (lambda: RunConfig(hand="shadow", calibrate_iterations=-1), "calibrate_iterations", "-1"),
    (lambda: RunConfig(hand="shadow", overrides=[("w", 1)]), "overrides", "list"),
    (lambda: keypoints_to_trajectory(KP, fps="120"), "fps", "'120' (str)"),
    (lambda: keypoints_to_trajectory(KP, fps=0), "fps", "> 0"),
    (lambda: keypoints_to_trajectory(KP, fps=1e400), "fps", "inf"),
    (lambda: keypoints_to_trajectory(KP, 120.0, order="mano"), "order", "'mano21'"),
    (lambda: keypoints_to_trajectory(np.zeros((4, 20, 3)), 120.0), "keypoints", "(4, 20, 3)"),
    (lambda: keypoints_to_trajectory("kp.npy", 120.0), "keypoints", "'kp.npy' (str)"),
    (lambda: keypoints_to_trajectory(np.full((4, 21, 3), np.nan), 120.0), "keypoints", "frame 0"),
    (lambda: retarget_keypoints(get_hand("leap"), KP, fps=None), "fps", "None"),
    (lambda: KeypointsConfig("leap", Path("k.npy"), "30", Path("o")), "fps", "'30' (str)"),
    (lambda: KeypointsConfig("leap", Path("k.npy"), 30.0, Path("o"), units="in"), "units", "'in'"),
    (lambda: RetargetConfig.from_overrides({"w_contacts": "1"}), "weight", "'1' (str)"),
    (lambda: RetargetConfig.from_overrides({"iterations": 2.0}), "iterations", "2.0"),
    (lambda: ValidateConfig(settle_s="0.3"), "ValidateConfig.settle_s", "'0.3' (str)"),
    (lambda: ValidateConfig(table=1), "ValidateConfig.table", "1 (int)"),
    (lambda: RefineConfig(retries="1"), "RefineConfig.retries", "'1' (str)"),
    (lambda: RefineConfig(tracker=None), "RefineConfig.tracker", "None"),
    (lambda: ForceCalibrationConfig(iterations=2.0), "ForceCalibrationConfig.iterations", "2.0"),
    (lambda: Retargeter("shadow"), "hand", "get_hand"),
    (lambda: Retargeter(get_hand("panda"), config={}), "config", "dict"),
    (lambda: retarget_demonstration(KP, "cube2/tripod", "panda"), "traj", "(4, 21, 3)"),
    (lambda: run_pipeline({"hand": "shadow"}), "cfg", "RunConfig(hand="),
    (lambda: run_retarget("shadow"), "cfg", "'shadow' (str)"),
    (lambda: run_metrics(None, None), "result", "PipelineResult"),
    (lambda: write_run("out", None, {}), "result", "PipelineResult"),
    (lambda: refine_lost(None, RefineConfig()), "result", "PipelineResult"),
]


def _ids(cases):
    return [f"{i}-{arg}" for i, (_, arg, _) in enumerate(cases)]


@pytest.mark.parametrize("call, arg, text", DEXCANVAS_CASES, ids=_ids(DEXCANVAS_CASES))
def test_dexcanvas_core_misuse_raises_its_error_naming_the_argument(call, arg, text):
    with pytest.raises(DexCanvasError) as e:
        call()
    msg = str(e.value)
    assert arg in msg and text in msg, msg
    assert "\n" not in msg


@pytest.mark.parametrize("call, arg, text", RETARGET_CASES, ids=_ids(RETARGET_CASES))
def test_retarget_misuse_raises_retarget_error_naming_the_argument(call, arg, text):
    with pytest.raises(RetargetError) as e:
        call()
    msg = str(e.value)
    assert arg in msg and text in msg, msg
    assert "\n" not in msg


def test_build_filter_still_takes_lists_tuples_and_codes():
    assert build_filter(objects=("cube2",)) == "index.scene IN ('cube2')"
    assert build_filter(manipulation_types=[1, "tripod"]) == (
        "trajectory_metadata.gesture IN ('1', 'tripod')"
    )
    assert build_filter(objects=[], extra="") is None


def test_checks_accept_numpy_scalars_and_refuse_bools():
    assert check_int("n", np.int64(3), min=0) == 3
    assert check_float("x", np.float32(0.5), positive=True) == 0.5
    assert check_str_seq("s", iter(["a", "b"])) == ("a", "b")
    assert check_array("a", [[1.0, 2.0]], (None, 2)).shape == (1, 2)
    for call in (lambda: check_int("n", True), lambda: check_float("x", False)):
        with pytest.raises(ValidationError, match=r"got (True|False) \(bool\)"):
            call()
    with pytest.raises(ValidationError, match=r"a must be finite, got nan at index \[0, 1\]"):
        check_array("a", [[1.0, np.nan]], (None, 2))


def test_valid_configs_are_unchanged():
    cfg = RunConfig(hand="shadow", pair="cube2/tripod", index=np.int64(1), force_scale=2)
    assert cfg.index == 1 and cfg.force_scale == 2 and cfg.dataset is None
    traj = keypoints_to_trajectory(KP, 120)
    assert traj.fps == 120.0 and traj.timestamp[1] == 1 / 120
