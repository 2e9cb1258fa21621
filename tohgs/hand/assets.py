"""Hand assets: the arrays a backend provides (torch-free), and the hand's forward kinematics in numpy.

:class:`HandAssets` is what ``results/hand/hand.npz`` holds. :meth:`HandAssets.vertices` poses the mesh
with the same kinematics as :class:`tohgs.hand.model.HandModel` (which is the differentiable, batched
torch version every optimiser and network uses), in float64 numpy and without importing torch: jobs that
only need hand meshes of given grasps (task expansion, one short job per task and object) then start in a
fraction of the time.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.hand.layout import FINGER_POSE_DIM, GRASP_DIM, N_BETAS, N_JOINTS, PARENTS

#: Contact candidates on the palm: the last ones of ``contact_ids`` (see :mod:`tohgs.hand.derived`).
PALM_CONTACTS = 8

#: Joints grouped by depth in the tree (wrist; first, second, third phalanges), for batched chaining.
LEVELS = ((0,), (1, 4, 7, 10, 13), (2, 5, 8, 11, 14), (3, 6, 9, 12, 15))


def rotvec_to_matrix(aa: np.ndarray) -> np.ndarray:
    """Rodrigues' formula in numpy: (..., 3) axis-angle (radians) -> (..., 3, 3), exact at zero angle."""
    aa = np.asarray(aa, dtype=np.float64)
    theta2 = (aa * aa).sum(-1)[..., None, None]
    small = theta2 < 1e-8
    theta = np.sqrt(np.where(small, 1.0, theta2))
    a = np.where(small, 1 - theta2 / 6, np.sin(theta) / theta)
    b = np.where(small, 0.5 - theta2 / 24, (1 - np.cos(theta)) / np.where(small, 1.0, theta2))
    x, y, z = aa[..., 0], aa[..., 1], aa[..., 2]
    zero = np.zeros_like(x)
    k = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(aa.shape[:-1] + (3, 3))
    return np.eye(3) + a * k + b * (k @ k)


@dataclass
class HandAssets:
    """Everything a backend provides, in MANO's canonical frame (metres, radians).

    Attributes:
        name: backend name (``anny`` or ``mano``).
        rest_vertices: (V, 3) flat-hand vertices at zero betas.
        shape_dirs: (V, 3, 10) vertex offsets per beta.
        pose_dirs: (V, 3, 135) pose blend shapes on (R - I) of the 15 finger joints, or ``None``.
        rest_joints: (16, 3) joint centres at zero betas.
        joint_shape_dirs: (16, 3, 10) joint offsets per beta.
        weights: (V, 16) skinning weights, rows sum to 1.
        faces: (F, 3) triangles as the model has them (open at the wrist).
        closed_faces: (F', 3) faces with the wrist sealed: a watertight closed surface.
        part_labels: (V,) in [0, 16): the joint with the largest skinning weight.
        tip_ids: (5,) fingertip vertex ids, in :data:`tohgs.hand.layout.TIP_ORDER`.
        contact_ids: (C,) palm-side contact-candidate vertex ids.
        joint_limits: (15, 3, 2) anatomical [min, max] per finger joint and canonical axis, radians.
        prior_mean, prior_std: (45,) pose prior of the finger parameters.
        presets: named (51,) pose vectors (``flat``, ``relaxed``, ``power``, ``pinch``).
        meta: provenance (versions, shape mapping) for the record.
    """

    name: str
    rest_vertices: np.ndarray
    shape_dirs: np.ndarray
    pose_dirs: np.ndarray | None
    rest_joints: np.ndarray
    joint_shape_dirs: np.ndarray
    weights: np.ndarray
    faces: np.ndarray
    closed_faces: np.ndarray
    part_labels: np.ndarray
    tip_ids: np.ndarray
    contact_ids: np.ndarray
    joint_limits: np.ndarray
    prior_mean: np.ndarray
    prior_std: np.ndarray
    presets: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    def validate(self, source: str = "hand assets") -> None:
        """Check shapes and basic invariants; raises ``ValueError`` naming ``source`` and the problem."""
        v = len(self.rest_vertices)
        expect = {
            "rest_vertices": (v, 3), "shape_dirs": (v, 3, N_BETAS), "rest_joints": (N_JOINTS, 3),
            "joint_shape_dirs": (N_JOINTS, 3, N_BETAS), "weights": (v, N_JOINTS), "part_labels": (v,),
            "tip_ids": (5,), "joint_limits": (15, 3, 2), "prior_mean": (FINGER_POSE_DIM,), "prior_std": (FINGER_POSE_DIM,),
        }
        if self.pose_dirs is not None:
            expect["pose_dirs"] = (v, 3, 135)
        for key, shape in expect.items():
            got = np.shape(getattr(self, key))
            if got != shape:
                raise ValueError(f"{source}: '{key}' has shape {got}, expected {shape}")
        for key in ("faces", "closed_faces"):
            f = np.asarray(getattr(self, key))
            if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= v:
                raise ValueError(f"{source}: '{key}' must be (F, 3) vertex ids in [0, {v})")
        if not np.allclose(self.weights.sum(1), 1.0, atol=1e-4):
            raise ValueError(f"{source}: skinning weights do not sum to 1")
        if not np.isfinite(self.rest_vertices).all():
            raise ValueError(f"{source}: non-finite rest vertices")

    @property
    def palm_ids(self) -> np.ndarray:
        """(8,) vertex ids of the palm's contact candidates; their mean is the palm centre."""
        return np.asarray(self.contact_ids)[-PALM_CONTACTS:]

    def joint_frames(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The posed joints' world frames of grasp vectors (zero betas), in float64: what skins the mesh.

        Args:
            pose: (B, 51) grasp vectors (see :meth:`vertices`).

        Returns:
            ``R`` (B, 16, 3, 3) the joints' rotations and ``P`` (B, 16, 3) their positions, m, with the grasp's
            translation: the rest vertex ``v`` skinned by joint ``j`` goes to ``R[j] (v - rest_joints[j]) +
            P[j]`` (before the pose blend shapes, which :meth:`vertices` adds in the rest frame).
        """
        R, P = self._frames(pose)
        return R, P + np.asarray(pose, dtype=np.float64)[:, None, :3]

    def _frames(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`joint_frames` before the grasp's translation (which :meth:`vertices` adds last, so that its
        vertices are the same numbers whether or not the frames are asked for)."""
        pose = np.asarray(pose, dtype=np.float64)
        if pose.ndim != 2 or pose.shape[1] != GRASP_DIM:
            raise ValueError(f"pose must have shape (B, {GRASP_DIM}), got {pose.shape}")
        b = len(pose)
        rot = rotvec_to_matrix(pose[:, 3:].reshape(b, N_JOINTS, 3))  # (B, 16, 3, 3)
        j = np.asarray(self.rest_joints, dtype=np.float64)
        R = np.empty_like(rot)
        P = np.empty((b, N_JOINTS, 3))
        R[:, 0], P[:, 0] = rot[:, 0], j[0]
        for level in LEVELS[1:]:
            ks = list(level)
            ps = [PARENTS[k] for k in ks]
            R[:, ks] = R[:, ps] @ rot[:, ks]
            P[:, ks] = P[:, ps] + (R[:, ps] @ (j[ks] - j[ps])[None, :, :, None])[..., 0]
        return R, P

    def vertices(self, pose: np.ndarray) -> np.ndarray:
        """Hand vertices of grasp vectors at zero betas, without torch.

        The same kinematics and skinning as :meth:`tohgs.hand.model.HandModel.forward` (tested equal), in
        float64.

        Args:
            pose: (B, 51) grasp vectors: translation (m), global axis-angle about the rest wrist joint, 15
                finger joints x axis-angle (radians), MANO joint order.

        Returns:
            (B, V, 3) vertices, m.
        """
        R, P = self._frames(pose)
        b = len(R)
        j = np.asarray(self.rest_joints, dtype=np.float64)
        v_rest = np.broadcast_to(np.asarray(self.rest_vertices, dtype=np.float64), (b,) + self.rest_vertices.shape)
        if self.pose_dirs is not None:
            rot = rotvec_to_matrix(np.asarray(pose, dtype=np.float64)[:, 3:].reshape(b, N_JOINTS, 3))
            feat = (rot[:, 1:] - np.eye(3)).reshape(b, 135)
            v_rest = v_rest + (feat @ np.asarray(self.pose_dirs, np.float64).reshape(-1, 135).T).reshape(b, -1, 3)
        A = np.concatenate([R, (P - (R @ j[None, :, :, None])[..., 0])[..., None]], -1)  # (B, 16, 3, 4)
        T = (np.asarray(self.weights, np.float64) @ A.reshape(b, N_JOINTS, 12)).reshape(b, -1, 3, 4)  # (B, V, 3, 4)
        return (T[..., :3] @ v_rest[..., None])[..., 0] + T[..., 3] + np.asarray(pose, dtype=np.float64)[:, None, :3]

    def save(self, path: str | Path) -> None:
        """Write to an ``.npz`` (atomically, byte-identical for identical assets: the archive's entries carry
        a fixed date, so rebuilding the same hand does not make the stages that read it look changed)."""
        from tohgs.io import atomic_path

        arrays: dict[str, Any] = {}
        for f in fields(self):
            val = getattr(self, f.name)
            if f.name == "presets":
                for k, p in val.items():
                    arrays[f"preset__{k}"] = np.asarray(p)
            elif f.name == "meta":
                import json

                arrays["meta_json"] = np.array(json.dumps(val))
            elif val is not None:
                arrays[f.name] = np.asarray(val)
        with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for name, arr in arrays.items():
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                with zf.open(info, "w", force_zip64=True) as out:
                    np.lib.format.write_array(out, arr, allow_pickle=False)

    @staticmethod
    def load(path: str | Path) -> "HandAssets":
        """Read what :meth:`save` wrote; raises ``ValueError`` naming the file if it is not one."""
        import json

        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except Exception as exc:
            raise ValueError(f"{path}: not a readable hand-assets file ({exc})") from exc
        presets = {k.split("__", 1)[1]: v for k, v in data.items() if k.startswith("preset__")}
        kwargs = {f.name: data.get(f.name) for f in fields(HandAssets) if f.name not in ("presets", "meta")}
        missing = [k for k, v in kwargs.items() if v is None and k != "pose_dirs"]
        if missing:
            raise ValueError(f"{path}: hand-assets file lacks {missing}")
        kwargs["name"] = str(kwargs["name"])
        assets = HandAssets(**kwargs, presets=presets, meta=json.loads(str(data.get("meta_json", "{}"))))
        assets.validate(str(path))
        return assets
