"""The MANO layout every hand backend follows: joints, parents, fingers, keypoints, canonical frame.

Canonical hand frame (MANO's): fingers along -x, palm facing -y, thumb on +z, wrist joint near the
origin, metres. The 51-number grasp vector is translation (3) + global axis-angle (3, about the rest
wrist joint) + 15 joints x axis-angle (3), each joint rotation relative to its parent and expressed in
the canonical frame's axes; zero is the flat hand.
"""

from __future__ import annotations

#: The 16 MANO joints in order.
JOINT_NAMES = (
    "wrist",
    "index1", "index2", "index3",
    "middle1", "middle2", "middle3",
    "pinky1", "pinky2", "pinky3",
    "ring1", "ring2", "ring3",
    "thumb1", "thumb2", "thumb3",
)
PARENTS = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)
N_JOINTS = 16
N_BETAS = 10

#: The grasp vector's parts, in order: the translation (m), the global rotation (axis-angle, rad) and the
#: finger pose (the 15 finger joints' axis-angles, rad: ``grasp[..., 6:]`` reshaped to (..., 15, 3)).
TRANSLATION_DIM = 3
GLOBAL_ROTATION_DIM = 3
FINGER_POSE_DIM = 3 * (N_JOINTS - 1)  # 45
#: The length of a grasp vector: 3 + 3 + 45 = 51 (its one home).
GRASP_DIM = TRANSLATION_DIM + GLOBAL_ROTATION_DIM + FINGER_POSE_DIM

#: Fingers in MANO joint order, each with its 3 joint indices.
FINGERS = {"index": (1, 2, 3), "middle": (4, 5, 6), "pinky": (7, 8, 9), "ring": (10, 11, 12), "thumb": (13, 14, 15)}

#: Fingertip order appended to the 16 joints to make the 21 keypoints (manopth's convention).
TIP_ORDER = ("thumb", "index", "middle", "ring", "pinky")

#: The 21 keypoint names: 16 joints, then the 5 fingertips.
KEYPOINT_NAMES = JOINT_NAMES + tuple(f"{f}_tip" for f in TIP_ORDER)


def children(joint: int) -> list[int]:
    """Direct children of ``joint``."""
    return [k for k, p in enumerate(PARENTS) if p == joint]


def descendants(joint: int) -> list[int]:
    """All joints below ``joint`` in the kinematic tree (not including it)."""
    out, stack = [], children(joint)
    while stack:
        k = stack.pop()
        out.append(k)
        stack += children(k)
    return sorted(out)
