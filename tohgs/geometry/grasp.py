"""The grasp vector's rigid transforms and poses: the one place they are written.

A grasp is :data:`tohgs.hand.layout.GRASP_DIM` = 51 numbers (the hand layout's, its one home): the hand's
translation (3, m), its global rotation as an axis-angle (3, rad) and the 15 finger joints' axis-angles
(45, rad), the MANO layout (:mod:`tohgs.hand.layout`). Poses are ``[x, y, z, qx, qy, qz, qw]`` (metres,
scipy's xyzw quaternion).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from tohgs.hand.layout import GRASP_DIM


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    """(4, 4) homogeneous matrix of a ``[x, y, z, qx, qy, qz, qw]`` pose (metres, scipy's xyzw quaternion)."""
    pose = np.asarray(pose, dtype=np.float64)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(pose[3:]).as_matrix()
    T[:3, 3] = pose[:3]
    return T


def transform_grasp(grasp: np.ndarray, T: np.ndarray, wrist: np.ndarray) -> np.ndarray:
    """The grasp vectors of hands moved rigidly by ``T``.

    The hand model turns its global rotation ``R_g`` about the rest wrist joint ``j0`` and then translates
    by ``t``: ``v = R_g (x - j0) + j0 + t``. Moving it by ``(R, p)`` gives ``R R_g`` and
    ``t' = R (j0 + t) + p - j0``; the 45 finger numbers do not change.

    Args:
        grasp: (B, 51) grasp vectors (translation m, axis-angles rad).
        T: (4, 4) rigid transform.
        wrist: (3,) the hand's rest wrist joint ``j0`` (``hand.rest_joints[0]``), m.

    Returns:
        (B, 51) grasp vectors in the new frame.
    """
    g = np.array(grasp, dtype=np.float64, copy=True).reshape(-1, GRASP_DIM)
    R, p = np.asarray(T, dtype=np.float64)[:3, :3], np.asarray(T, dtype=np.float64)[:3, 3]
    j0 = np.asarray(wrist, dtype=np.float64)
    g[:, 3:6] = (Rotation.from_matrix(R) * Rotation.from_rotvec(g[:, 3:6])).as_rotvec()
    g[:, :3] = (j0 + g[:, :3]) @ R.T + p - j0
    return g
