"""What every backend derives the same way from its rest mesh and skeleton.

- ``closed_faces``: the wrist opening sealed with a fan of triangles over its boundary loop.
- ``part_labels``: per vertex, the joint with the largest skinning weight (ContactGen's 16 parts).
- ``tip_ids``: per finger, the distal-part vertex farthest along the distal phalanx.
- ``contact_ids``: palm-side vertices spread over every phalanx and the palm, DexGraspNet-MANO's
  proportions (thumb 14, index/middle/ring 17, pinky 11, palm 8).
- ``joint_limits``: anatomical ranges of flexion, abduction and twist per joint, expressed as a box in
  the canonical frame's axes (what the 51-number vector holds).
- ``presets`` (flat, relaxed, power, pinch) and the pose prior (mean = relaxed, spread = a quarter of each
  joint range).

Each finger joint gets an anatomical frame from the flat rest skeleton: flexion axis ``a = d x n`` (``d``
the phalanx direction, ``n`` the palm normal -y, so that a positive angle curls the finger toward the
palm), abduction axis ``n`` and twist axis ``d``.
"""

from __future__ import annotations

import numpy as np
import trimesh

from tohgs.hand.layout import FINGER_POSE_DIM, FINGERS, GRASP_DIM, N_JOINTS, PARENTS, TIP_ORDER, children
from tohgs.hand.assets import PALM_CONTACTS, HandAssets

PALM_NORMAL = np.array([0.0, -1.0, 0.0])

#: Anatomical ranges in degrees: (flexion, abduction, twist) x (min, max), per joint level.
FINGER_RANGES = {1: ((-10, 90), (-20, 20), (-10, 10)),   # MCP
                 2: ((-5, 110), (-5, 5), (-5, 5)),        # PIP
                 3: ((-5, 90), (-5, 5), (-5, 5))}         # DIP
THUMB_RANGES = {1: ((-30, 70), (-40, 40), (-40, 40)),    # CMC
                2: ((-10, 60), (-15, 15), (-15, 15)),     # MCP
                3: ((-15, 90), (-5, 5), (-5, 5))}         # IP

#: Presets as flexion angles in degrees per finger and level (abduction and twist zero), thumb last.
PRESET_FLEXION = {
    "flat": {f: (0, 0, 0) for f in FINGERS},
    "relaxed": {"index": (15, 20, 10), "middle": (18, 22, 10), "ring": (20, 24, 12), "pinky": (22, 26, 12),
                "thumb": (10, 10, 10)},
    "power": {"index": (55, 75, 45), "middle": (60, 75, 45), "ring": (62, 75, 45), "pinky": (65, 75, 45),
              "thumb": (40, 30, 30)},
    "pinch": {"index": (40, 45, 25), "middle": (30, 40, 20), "ring": (35, 45, 25), "pinky": (40, 45, 25),
              "thumb": (45, 20, 20)},
}
#: Thumb opposition in the presets: abduction of the thumb's first joint toward the fingers, degrees.
PRESET_THUMB_ABDUCTION = {"flat": 0, "relaxed": 10, "power": 32, "pinch": 38}
#: Contact candidates per finger level (joint 1, 2, 3) and on the palm.
CONTACT_COUNTS = {"thumb": (4, 5, 5), "index": (6, 6, 5), "middle": (6, 6, 5), "ring": (6, 6, 5),
                  "pinky": (4, 4, 3), "palm": PALM_CONTACTS}


def seal_wrist(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Close every boundary loop of an open mesh with a fan of triangles (wound to match).

    Returns:
        (F + sum(len(loop) - 2), 3) faces; the mesh is closed if the input's only holes are simple loops.
    """
    faces = np.asarray(faces, dtype=np.int64)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = {tuple(e) for e in directed.tolist()}
    boundary = [tuple(e) for e in directed.tolist() if (e[1], e[0]) not in key]
    nxt = {a: b for a, b in boundary}
    if len(nxt) != len(boundary):
        raise ValueError("boundary is not a set of simple loops (a vertex starts two boundary edges)")
    caps, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop = [start]
        while nxt[loop[-1]] != start:
            loop.append(nxt[loop[-1]])
            if len(loop) > len(nxt):
                raise ValueError("open boundary chain")
        seen.update(loop)
        caps += [(loop[0], loop[i + 1], loop[i]) for i in range(1, len(loop) - 1)]
    return np.concatenate([faces, np.asarray(caps, dtype=np.int64).reshape(-1, 3)])


def _fps(points: np.ndarray, k: int, start: int) -> np.ndarray:
    """Farthest point sampling of ``k`` indices into ``points`` (N, 3), from index ``start``."""
    k = min(k, len(points))
    chosen = [start]
    d = np.linalg.norm(points - points[start], axis=1)
    for _ in range(k - 1):
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(points - points[i], axis=1))
    return np.asarray(chosen)


def joint_frames(joints: np.ndarray) -> np.ndarray:
    """(15, 3, 3) anatomical frames of the finger joints: columns (flexion, abduction, twist) axes."""
    frames = np.zeros((15, 3, 3))
    for k in range(1, N_JOINTS):
        kids = children(k)
        tip = joints[kids[0]] if kids else joints[k] + (joints[k] - joints[PARENTS[k]])
        d = tip - joints[k]
        d /= np.linalg.norm(d)
        a = np.cross(d, PALM_NORMAL)
        a /= np.linalg.norm(a)
        n = np.cross(a, d)  # the palm-normal direction made orthogonal to d and a
        frames[k - 1] = np.stack([a, n, d], 1)
    return frames


def _level_ranges() -> np.ndarray:
    """(15, 3, 2) anatomical ranges in radians per joint: (flexion, abduction, twist) x (min, max)."""
    out = np.zeros((15, 3, 2))
    for finger, ks in FINGERS.items():
        table = THUMB_RANGES if finger == "thumb" else FINGER_RANGES
        for level, k in enumerate(ks, start=1):
            out[k - 1] = np.deg2rad(np.asarray(table[level], dtype=np.float64))
    return out


def canonical_limits(frames: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Box in canonical axes that holds every rotation ``frame @ (flex, abd, twist)`` within ``ranges``."""
    lo = np.einsum("kic,kc->ki", np.clip(frames, 0, None), ranges[..., 0]) + \
        np.einsum("kic,kc->ki", np.clip(frames, None, 0), ranges[..., 1])
    hi = np.einsum("kic,kc->ki", np.clip(frames, 0, None), ranges[..., 1]) + \
        np.einsum("kic,kc->ki", np.clip(frames, None, 0), ranges[..., 0])
    return np.stack([lo, hi], -1)


def preset_pose(frames: np.ndarray, flexion_deg: dict[str, tuple[float, float, float]],
                thumb_abduction_deg: float = 0.0) -> np.ndarray:
    """(51,) pose vector: zero translation and global rotation, flexion angles about each joint's axis,
    and the thumb's first joint abducted toward the fingers by ``thumb_abduction_deg`` (opposition)."""
    pose = np.zeros(GRASP_DIM)
    for finger, ks in FINGERS.items():
        for level, k in enumerate(ks):
            pose[3 + 3 * k: 6 + 3 * k] = np.deg2rad(flexion_deg[finger][level]) * frames[k - 1][:, 0]
    k = FINGERS["thumb"][0]
    pose[3 + 3 * k: 6 + 3 * k] += np.deg2rad(thumb_abduction_deg) * frames[k - 1][:, 1]
    return pose


def complete_assets(a: HandAssets) -> HandAssets:
    """Fill in everything derived from the rest mesh and skeleton (see the module docstring)."""
    v, j = a.rest_vertices, a.rest_joints
    a.closed_faces = seal_wrist(v, a.faces)
    a.part_labels = np.argmax(a.weights, axis=1).astype(np.int64)
    normals = trimesh.Trimesh(v, a.closed_faces, process=False).vertex_normals
    # Fingertips: the distal-part vertex farthest along the distal phalanx.
    tips = []
    for finger in TIP_ORDER:
        k1, k2, k3 = FINGERS[finger]
        d = j[k3] - j[k2]
        idx = np.flatnonzero(a.part_labels == k3)
        tips.append(idx[np.argmax((v[idx] - j[k3]) @ d)])
    a.tip_ids = np.asarray(tips, dtype=np.int64)
    # Contact candidates: palm-side vertices of each part, spread by farthest point sampling.
    palm_side = normals @ PALM_NORMAL > np.cos(np.deg2rad(50))

    def spread(idx: np.ndarray, count: int, where: str) -> list[int]:
        if len(idx) < count:
            raise ValueError(f"{a.name}: only {len(idx)} palm-side vertices on {where}")
        start = np.argmin(np.linalg.norm(v[idx] - v[idx].mean(0), axis=1))
        return idx[_fps(v[idx], count, int(start))].tolist()

    contact = []
    for finger, ks in FINGERS.items():
        for k, count in zip(ks, CONTACT_COUNTS[finger]):
            contact += spread(np.flatnonzero(palm_side & (a.part_labels == k)), count, f"joint {k}")
    # Palm: between the wrist and the knuckles, away from the wrist opening.
    knuckles = j[[1, 4, 7, 10]]
    along = knuckles.mean(0) - j[0]
    t = (v - j[0]) @ along / (along @ along)
    contact += spread(np.flatnonzero(palm_side & (a.part_labels == 0) & (t > 0.25) & (t < 0.95)),
                      CONTACT_COUNTS["palm"], "the palm")
    a.contact_ids = np.asarray(contact, dtype=np.int64)
    # Joint limits, presets and the pose prior.
    frames = joint_frames(j)
    ranges = _level_ranges()
    a.joint_limits = canonical_limits(frames, ranges)
    a.presets = {name: preset_pose(frames, flex, PRESET_THUMB_ABDUCTION[name]) for name, flex in PRESET_FLEXION.items()}
    a.prior_mean = a.presets["relaxed"][6:].copy()
    a.prior_std = np.maximum((a.joint_limits[..., 1] - a.joint_limits[..., 0]).reshape(FINGER_POSE_DIM) / 4, 0.05)
    a.meta = {**a.meta, "anatomical_ranges_deg": np.rad2deg(ranges).round(3).tolist(),
              "joint_frames": frames.round(6).tolist()}
    a.validate(a.name)
    return a
