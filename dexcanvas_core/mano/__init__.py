"""MANO-compatible human hand: one ``ManoLayer`` API, exact MANO when the model files are present.

* ``ManoLayer`` (``layer.py``): batched, differentiable forward from (betas, global orientation,
  45-D pose, translation) to 16 joints, 21 keypoints and, with the official model, the 778-vertex
  mesh; ``forward_numpy`` for numpy in/out.
* ``HandSkeleton``, ``measure_bone_lengths`` (``skeleton.py``): the built-in skeleton used without
  model files, and a subject's bone lengths measured from DexCanvas ``mano_joint_pos``.
* ``load_mano_model`` (``model_file.py``): reads the official pickles without chumpy.
* ``axis_angle_to_matrix``, ``forward_kinematics`` (``kinematics.py``), ``mano_lbs`` (``lbs.py``).
* ``HandModel``, ``hand_model`` (``hand_model.py``): batched numpy kinematics of 22 driven
  anatomical angles and the capsule collision model (``CAPSULES``) that the demonstration
  generator, the force pipeline and the viewers share.

Keypoint orderings and converters live in ``dexcanvas_core.keypoints``.
"""

from dexcanvas_core.mano.kinematics import axis_angle_to_matrix, forward_kinematics
from dexcanvas_core.mano.layer import (
    MANO_TIP_VERTEX_IDS,
    NUM_BETAS,
    ManoLayer,
    ManoOutput,
)
from dexcanvas_core.mano.lbs import mano_lbs
from dexcanvas_core.mano.model_file import (
    MANO_MODEL_DIR_ENV,
    MANO_MODEL_FILES,
    ManoModelData,
    load_mano_model,
    read_model_pickle,
    resolve_model_file,
)
from dexcanvas_core.mano.pose import mirror_axis_angle, split_full_pose
from dexcanvas_core.mano.skeleton import (
    BETA0_SCALE_PER_UNIT,
    BONE_NAMES,
    BUCHHOLZ_SEGMENT_RATIOS,
    FINGER_BONES,
    MANO21_PARENTS,
    TIP_PARENTS,
    HandSkeleton,
    measure_bone_lengths,
)

__all__ = [
    "BETA0_SCALE_PER_UNIT",
    "BONE_NAMES",
    "BUCHHOLZ_SEGMENT_RATIOS",
    "FINGER_BONES",
    "MANO21_PARENTS",
    "MANO_MODEL_DIR_ENV",
    "MANO_MODEL_FILES",
    "MANO_TIP_VERTEX_IDS",
    "NUM_BETAS",
    "TIP_PARENTS",
    "HandSkeleton",
    "ManoLayer",
    "ManoModelData",
    "ManoOutput",
    "axis_angle_to_matrix",
    "forward_kinematics",
    "load_mano_model",
    "mano_lbs",
    "measure_bone_lengths",
    "mirror_axis_angle",
    "read_model_pickle",
    "resolve_model_file",
    "split_full_pose",
]
