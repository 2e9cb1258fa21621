"""Task expansion (paper section 3.2): prior grasps that stay collision-free with the target at both poses.

For every scene configuration, each accepted prior grasp of the target (a 51-number grasp in the object's
mesh frame) is placed with the target at its initial pose and carried rigidly to its goal pose. The grasp
is kept for that configuration if, at both poses, no hand vertex lies deeper than ``tolerance`` inside a
scene mesh other than the target (the table or shelf, the obstacles, the base brick). Inside-ness is
open3d's ray-casting occupancy; the depth is the unsigned distance to the scene's surface.

The hand meshes come from :meth:`tohgs.hand.assets.HandAssets.vertices`, so a task-expansion job never
imports torch (its start-up was most of the job's time).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from tohgs.geometry.grasp import pose_matrix, transform_grasp
from tohgs.geometry.scene import SceneCollider, collision_free, scene_meshes
from tohgs.hand.assets import HandAssets
from tohgs.hand.layout import GRASP_DIM

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ExpansionSettings:
    """``tolerance``: largest depth of a hand vertex inside a scene mesh that is not a collision, m."""

    tolerance: float = 0.002


def expand_configurations(scenes, prior_pose: np.ndarray, hand: HandAssets, objects_dir: str | Path, supports: dict,
                          settings: ExpansionSettings) -> dict[str, np.ndarray]:
    """Task grasps of every configuration of one scene set.

    Args:
        scenes: a :class:`~tohgs.data.scenes.SceneSet`.
        prior_pose: (A, 51) accepted prior grasps in the target's mesh frame.
        hand: the hand's assets (a :class:`~tohgs.hand.model.HandModel` has them as ``.assets``).
        objects_dir: the objects stage's folder.
        supports: the supports by name.
        settings: the collision tolerance.

    Returns:
        ``config`` (K,), ``prior_index`` (K,), ``grasp_init`` and ``grasp_goal`` (K, 51) world-frame grasp
        vectors, ``kept_per_config`` (C,), and ``rejected_init`` / ``rejected_goal`` (C,): per configuration
        the prior grasps the scene rejects at the initial / the goal pose (a grasp may be rejected at both):
        how hard the scene is, whatever method is run on it.
    """
    if len(prior_pose) == 0:
        log.warning("%s %s: no accepted prior grasp, so no task grasp", scenes.task, scenes.object)
        return {"config": np.zeros(0, np.int32), "prior_index": np.zeros(0, np.int32),
                "grasp_init": np.zeros((0, GRASP_DIM), np.float32), "grasp_goal": np.zeros((0, GRASP_DIM), np.float32),
                "kept_per_config": np.zeros(len(scenes), np.int64),
                "rejected_init": np.zeros(len(scenes), np.int64), "rejected_goal": np.zeros(len(scenes), np.int64)}
    local = hand.vertices(prior_pose)  # (A, V, 3) in the target's mesh frame
    wrist = np.asarray(hand.rest_joints[0], dtype=np.float64)
    cache: dict[str, trimesh.Trimesh] = {}
    rows: dict[str, list] = {"config": [], "prior_index": [], "grasp_init": [], "grasp_goal": []}
    kept = np.zeros(len(scenes), dtype=np.int64)
    rejected = np.zeros((2, len(scenes)), dtype=np.int64)  # at the initial, at the goal pose
    for c in range(len(scenes)):
        collider = SceneCollider(scene_meshes(scenes, c, objects_dir, supports, cache))
        ok = np.ones(len(local), dtype=bool)
        for p, pose in enumerate((scenes.target_init_pose[c], scenes.target_goal_pose[c])):
            T = pose_matrix(pose)
            world = local @ T[:3, :3].T + T[:3, 3]
            free = collision_free(world, collider, settings.tolerance)
            rejected[p, c] = int((~free).sum())
            ok &= free
        idx = np.flatnonzero(ok)
        kept[c] = len(idx)
        rows["config"] += [c] * len(idx)
        rows["prior_index"] += idx.tolist()
        rows["grasp_init"].append(transform_grasp(prior_pose[idx], pose_matrix(scenes.target_init_pose[c]), wrist))
        rows["grasp_goal"].append(transform_grasp(prior_pose[idx], pose_matrix(scenes.target_goal_pose[c]), wrist))
        log.info("%s %s configuration %d: %d of %d grasps kept", scenes.task, scenes.object, c, len(idx), len(local))
    return {"config": np.asarray(rows["config"], dtype=np.int32),
            "prior_index": np.asarray(rows["prior_index"], dtype=np.int32),
            "grasp_init": np.concatenate(rows["grasp_init"]).astype(np.float32) if rows["grasp_init"] else np.zeros((0, GRASP_DIM), np.float32),
            "grasp_goal": np.concatenate(rows["grasp_goal"]).astype(np.float32) if rows["grasp_goal"] else np.zeros((0, GRASP_DIM), np.float32),
            "kept_per_config": kept, "rejected_init": rejected[0], "rejected_goal": rejected[1]}


def make_task_grasps(scene_store: str | Path, prior_store: str | Path, objects_dir: str | Path,
                     supports_json: str | Path, hand: HandAssets, settings: dict, out: str | Path) -> dict[str, np.ndarray]:
    """The task grasps of one task and target object: expand its accepted prior grasps over its scene
    configurations and write ``out`` (:mod:`tohgs.data.task_grasps`)."""
    from tohgs.assets.supports import read_supports
    from tohgs.data.grasps import read_prior_grasps
    from tohgs.data.scenes import read_scenes
    from tohgs.data.task_grasps import write_task_grasps

    scenes = read_scenes(scene_store)
    prior = read_prior_grasps(prior_store, filtered=True)
    if prior.object != scenes.object:
        raise ValueError(f"{prior_store} holds grasps of {prior.object}, but {scene_store} is about {scenes.object}")
    s = ExpansionSettings(**settings)
    accepted = prior.pose[prior.passed]
    out_arrays = expand_configurations(scenes, accepted, hand, objects_dir, read_supports(supports_json), s)
    out_arrays["prior_index"] = np.flatnonzero(prior.passed)[out_arrays["prior_index"]].astype(np.int32)
    kept = out_arrays["kept_per_config"]
    rejected = {k: out_arrays.pop(k).tolist() for k in ("rejected_init", "rejected_goal")}
    log.info("%s %s: %d accepted prior grasps -> %d task grasps over %d configurations (per configuration: %s)",
             scenes.task, scenes.object, len(accepted), int(kept.sum()), len(kept), kept.tolist())
    write_task_grasps(out_arrays, {"task": scenes.task, "object": scenes.object, "n_prior_accepted": int(len(accepted)),
                                   "config": {"tolerance": s.tolerance}, **rejected}, out)
    return out_arrays
