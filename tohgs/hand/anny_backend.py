"""The open default hand: the ``anny`` package's right hand (Apache-2.0 code, CC0 MakeHuman assets).

``anny.Anny(rig='anny-hand.R', topology='hand.R')`` is a skinned right hand with 1609 vertices, 3196
triangles (open at the wrist) and 21 bones. :func:`build_anny_assets` turns it, once, into MANO-layout
:class:`~tohgs.hand.model.HandAssets`; after that tohgs skins it with its own torch code (no Warp kernels,
any device), from an ``.npz`` cache keyed by the anny version.

Mapping, documented here because every user of the grasp vector depends on it:

- Bones -> MANO's 16 joints: ``wrist`` = anny's root, wrist and the four metacarpals (held at rest, so
  their skinning weights merge into the wrist's); ``index1-3`` = ``finger2-1..3``; ``middle1-3`` =
  ``finger3-1..3``; ``ring1-3`` = ``finger4-1..3``; ``pinky1-3`` = ``finger5-1..3``; ``thumb1-3`` =
  ``finger1-1..3``. Joint centres are the bone heads; the wrist joint is anny's wrist head.
- Frame: anny places the hand where it sits on its body; the canonical frame is computed from the
  skeleton: origin at the wrist joint, -x along wrist -> middle knuckle, +z toward the thumb side (the
  pinky -> index knuckle direction, made orthogonal), y = z x x; the build checks that the rest fingers
  curl toward -y (the palm side), i.e. that this is a right hand in MANO's canonical frame.
- Flat hand: anny's rest fingers are slightly curled; the flat hand (zero pose) straightens each finger
  along its metacarpal and the thumb's distal phalanges along its proximal one. The straightening is
  baked into the rest mesh at the average hand.
- Shape: the 10 betas map onto anny's six phenotypes (gender, age, muscle, weight, height,
  proportions) and four local hand changes (hand scale, finger length, finger diameter, finger
  distance): beta_i = +-1 is phenotype_i = 0.5 +- 0.25 (local change +-0.5). Zero betas are anny's
  average adult hand. The shape directions are central differences at the average hand, so the map is
  linear as MANO's is (anny's own response to phenotypes is piecewise linear).
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import numpy as np

from tohgs.hand.layout import FINGER_POSE_DIM, PARENTS
from tohgs.hand.assets import HandAssets

log = logging.getLogger(__name__)

#: anny bone index -> MANO joint index (for the 21 bones of anny-hand.R, see module docstring).
ANNY_TO_MANO = {0: 0, 1: 0, 5: 0, 9: 0, 13: 0, 17: 0,
                2: 13, 3: 14, 4: 15,
                6: 1, 7: 2, 8: 3,
                10: 4, 11: 5, 12: 6,
                14: 10, 15: 11, 16: 12,
                18: 7, 19: 8, 20: 9}
#: MANO joint index -> anny bone whose head is the joint centre.
MANO_JOINT_BONE = (1, 6, 7, 8, 10, 11, 12, 18, 19, 20, 14, 15, 16, 2, 3, 4)
#: The metacarpal bone each finger's first phalanx straightens along (MANO first-joint index -> bone).
METACARPAL_OF = {1: 5, 4: 9, 10: 13, 7: 17}

PHENOTYPES = ("gender", "age", "muscle", "weight", "height", "proportions")
LOCAL_CHANGES = ("r-hand-scale-incr", "r-hand-fingers-length-incr", "r-hand-fingers-diameter-incr",
                 "r-hand-fingers-distance-incr")
PHENOTYPE_STEP = 0.25  # phenotype change per unit beta
LOCAL_STEP = 0.5  # local-change value per unit beta



def canonical_frame(joints: np.ndarray, curled_tip: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose rows are the canonical x, y, z axes, from MANO-ordered joints (16, 3).

    ``curled_tip`` is a curled fingertip position used to check the palm side.

    Raises:
        RuntimeError: the skeleton is not a right hand (the fingers curl toward +y).
    """
    x = joints[0] - joints[4]
    x /= np.linalg.norm(x)
    side = joints[1] - joints[7]  # pinky knuckle -> index knuckle: toward the thumb
    z = side - (side @ x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    r = np.stack([x, y, z])
    curl = r @ (curled_tip - joints[4])
    if curl[1] >= 0:
        raise RuntimeError("the anny hand does not curl toward -y in the canonical frame: not a right hand?")
    return r


def anny_version() -> str:
    from importlib.metadata import version

    return version("anny")


def default_cache_dir() -> Path:
    """``$TOHGS_CACHE`` or ``~/.cache/tohgs``: where the extracted hand is kept."""
    return Path(os.environ.get("TOHGS_CACHE", Path.home() / ".cache" / "tohgs"))


def _anny_raw() -> dict[str, np.ndarray]:
    """Evaluate anny (its one-time Warp compile happens here) at the average hand and around it."""
    import torch
    import anny

    t0 = time.perf_counter()
    log.info("building the anny hand (first use compiles Warp kernels and may take a minute or more)")
    model = anny.Anny(rig="anny-hand.R", topology="hand.R", local_changes=list(LOCAL_CHANGES))
    if list(model.phenotype_labels) != list(PHENOTYPES):
        raise RuntimeError(f"anny {anny_version()}: unexpected phenotypes {model.phenotype_labels}")
    n = 1 + 2 * 10
    phen = torch.full((n, 6), 0.5, dtype=torch.float64)
    local = torch.zeros((n, len(model.local_change_labels)), dtype=torch.float64)
    local_idx = [list(model.local_change_labels).index(lc) for lc in LOCAL_CHANGES]
    for i in range(10):
        for s, row in ((1.0, 1 + 2 * i), (-1.0, 2 + 2 * i)):
            if i < 6:
                phen[row, i] += s * PHENOTYPE_STEP
            else:
                local[row, local_idx[i - 6]] = s * LOCAL_STEP
    with torch.no_grad():
        out = model(phenotype_kwargs=phen, local_changes_kwargs=local)
    bone_idx = model.vertex_bone_indices.cpu().numpy()
    bone_w = model.vertex_bone_weights.cpu().numpy()
    weights = np.zeros((bone_idx.shape[0], model.bone_count))
    np.add.at(weights, (np.arange(len(bone_idx))[:, None].repeat(bone_idx.shape[1], 1), bone_idx), bone_w)
    log.info("anny hand evaluated in %.1f s", time.perf_counter() - t0)
    return {
        "rest_vertices": out["rest_vertices"].cpu().numpy(),  # (n, V, 3)
        "bone_heads": out["rest_bone_heads"].cpu().numpy(),  # (n, 21, 3)
        "bone_poses": out["rest_bone_poses"].cpu().numpy(),  # (n, 21, 4, 4)
        "weights": weights,  # (V, 21)
        "faces": model.faces.cpu().numpy().astype(np.int64),
        "parents": np.asarray(model.bone_parents),
        "labels": np.asarray(model.bone_labels),
    }


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b`` (3x3)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + 1e-9:
        raise ValueError("cannot align opposite vectors")
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def _flatten(rest: np.ndarray, heads: np.ndarray, poses: np.ndarray, weights21: np.ndarray, frame: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Straighten anny's curled rest fingers with linear blend skinning.

    ``frame`` is the canonical frame (rows x, y, z): the thumb's proximal phalanx is turned into the palm
    plane (its component along y removed), as in MANO's flat hand, and its distal phalanges along it.

    Returns the flat vertices (V, 3), the flat MANO joints (16, 3), the per-vertex blended rotation
    (V, 3, 3) and the per-joint global rotation (16, 3, 3) that carry shape directions along, and the
    skinning weights merged onto the 16 joints (V, 16).
    """
    joints = heads[list(MANO_JOINT_BONE)]  # (16, 3)
    axis = poses[:, :3, 1]  # Blender bones point along their local y
    g = np.repeat(np.eye(3)[None], 16, 0)  # global rotation per MANO joint
    for first, mc in METACARPAL_OF.items():
        for k in (first, first + 1, first + 2):
            g[k] = _align(axis[MANO_JOINT_BONE[k]], axis[mc])
    thumb = axis[MANO_JOINT_BONE[13]]
    thumb_flat = thumb - (thumb @ frame[1]) * frame[1]
    g[13] = _align(thumb, thumb_flat)
    for k in (14, 15):  # thumb: distal phalanges along the flattened proximal one
        g[k] = _align(axis[MANO_JOINT_BONE[k]], thumb_flat)
    # World positions of the joints under the global rotations (each about its own rest joint).
    pos = joints.copy()
    for k in range(1, 16):
        p = PARENTS[k]
        pos[k] = pos[p] + g[p] @ (joints[k] - joints[p])
    # Skin: merge anny bones into the 16 joints.
    w16 = np.zeros((len(rest), 16))
    for bone, j in ANNY_TO_MANO.items():
        w16[:, j] += weights21[:, bone]
    trans = pos - np.einsum("kij,kj->ki", g, joints)
    blend_r = np.einsum("vk,kij->vij", w16, g)
    flat = np.einsum("vij,vj->vi", blend_r, rest) + w16 @ trans
    return flat, pos, blend_r, g, w16


def build_anny_assets() -> HandAssets:
    """Extract anny's right hand into MANO-layout :class:`HandAssets` (slow once: anny's build and Warp)."""
    from tohgs.hand.derived import complete_assets

    raw = _anny_raw()
    labels = list(raw["labels"])
    expected = ["root", "wrist.R", "finger1-1.R", "finger1-2.R", "finger1-3.R", "metacarpal1.R"]
    if labels[:6] != expected or len(labels) != 21:
        raise RuntimeError(f"anny {anny_version()}: unexpected hand bones {labels}")
    w21 = raw["weights"]
    heads = raw["bone_heads"][0]
    c = canonical_frame(heads[list(MANO_JOINT_BONE)], heads[MANO_JOINT_BONE[6]])
    flat, joints, blend_r, g, w16 = _flatten(raw["rest_vertices"][0], heads, raw["bone_poses"][0], w21, c)
    # Shape directions: central differences of the curled rest shapes, carried into the flat pose.
    rv, bh = raw["rest_vertices"], raw["bone_heads"]
    dv = np.stack([(rv[1 + 2 * i] - rv[2 + 2 * i]) / 2 for i in range(10)], -1)  # (V, 3, 10)
    dj = np.stack([(bh[1 + 2 * i] - bh[2 + 2 * i]) / 2 for i in range(10)], -1)[list(MANO_JOINT_BONE)]
    dv = np.einsum("vij,vjl->vil", blend_r, dv)
    parent_rot = np.stack([np.eye(3)] + [g[PARENTS[k]] for k in range(1, 16)])  # a joint moves with its parent
    dj = np.einsum("kij,kjl->kil", parent_rot, dj)
    origin = joints[0]
    assets = HandAssets(
        name="anny",
        rest_vertices=(flat - origin) @ c.T,
        shape_dirs=np.einsum("ij,vjl->vil", c, dv),
        pose_dirs=None,
        rest_joints=(joints - origin) @ c.T,
        joint_shape_dirs=np.einsum("ij,kjl->kil", c, dj),
        weights=w16 / w16.sum(1, keepdims=True),
        faces=raw["faces"],
        closed_faces=raw["faces"],  # sealed by complete_assets
        part_labels=np.zeros(len(flat), dtype=np.int64),
        tip_ids=np.zeros(5, dtype=np.int64),
        contact_ids=np.zeros(0, dtype=np.int64),
        joint_limits=np.zeros((15, 3, 2)),
        prior_mean=np.zeros(FINGER_POSE_DIM),
        prior_std=np.ones(FINGER_POSE_DIM),
        meta={"backend": "anny", "anny_version": anny_version(), "phenotypes": list(PHENOTYPES),
              "local_changes": list(LOCAL_CHANGES), "phenotype_step": PHENOTYPE_STEP, "local_step": LOCAL_STEP},
    )
    return complete_assets(assets)


def _code_hash() -> str:
    """Hash of the modules that shape the extracted hand: a code change rebuilds the cache entry."""
    import hashlib

    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for name in ("anny_backend.py", "assets.py", "derived.py", "layout.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()[:12]


def load_anny_assets(cache_dir: str | Path | None = None) -> HandAssets:
    """The anny hand assets, built on first use and cached as
    ``<cache_dir>/hand-anny-<anny version>-<code hash>.npz``."""
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache / f"hand-anny-{anny_version()}-{_code_hash()}.npz"
    if path.is_file():
        try:
            return HandAssets.load(path)
        except ValueError as exc:
            log.warning("rebuilding the anny hand: %s", exc)
    assets = build_anny_assets()
    path.parent.mkdir(parents=True, exist_ok=True)
    assets.save(path)
    log.info("cached the anny hand at %s", path)
    return assets
