"""Per-grasp evaluation of a method's test predictions (the paper's section 5.2), one row per grasp.

For every predicted grasp of a test configuration (a prediction store, :mod:`tohgs.data.predictions`):

- ``pv`` (m^3), ``sd`` (m), ``contact_distance`` (m): the quality metrics of :mod:`tohgs.metrics.quality`
  (the same functions the prior-grasp filter uses), with the target at its *initial* pose in the world
  frame. The paper's protocol by default: PV voxelises the target's convex parts (``pv_mesh``
  ``"collision"``: the official code voxelises its decomposed mesh; ``"mesh"``, the watertight mesh), SD's
  gravity is the official fixed (0, 9.8, 0) m/s^2 of the world frame (``evaluation.sd_gravity``);
- ``sd_palm`` (m, beyond the paper, with ``palm_sd``): SD again with gravity pulling the target out of the
  palm (:func:`tohgs.metrics.quality.palm_gravity`), NaN without;
- the hand SD simulates (``evaluation.sd_hand``, ``sd_hand``): its closed mesh (``"full"``) or a decimated
  collision hand of a triangle count (:mod:`tohgs.hand.collision`), posed from the full hand's vertices;
  SD, robust SD and palm SD simulate it, every other metric (PV above all) keeps the full mesh;
- ``init_opp`` / ``goal_opp``: the fraction of hand vertices inside the scene meshes (support, shelf,
  obstacles, base brick; never the target) for the hand at the initial pose and for the same hand carried
  to the goal pose;
- ``ds``: the configuration's diversity, repeated on each of its rows: the mean over all pairs of its
  grasps of the summed per-vertex L2 distance between the two hands (at the initial pose), m. It scales
  with the hand's vertex count, which each row records (``hand_vertices``; MANO has 778);
- ``kept``: False for a grasp the method discarded (the prediction store's ``kept``, F-GraspTTA's
  filter): its row is kept, so that the tables can count it, with NaN metrics (it is not simulated), and
  the configuration's DS is of its kept grasps.

The table-level numbers (CR, QR, TS and the QR grid) are computed from these rows by
:mod:`tohgs.metrics.tables`, so a QR threshold change re-reads the rows and reruns nothing else.
"""

from __future__ import annotations

import dataclasses
import logging
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import trimesh

from tohgs.assets.mesh import collision_mesh, object_mesh
from tohgs.settings import settings_from
from tohgs.data.predictions import read_predictions
from tohgs.data.scenes import read_scenes
from tohgs.geometry.grasp import pose_matrix
from tohgs.geometry.scene import SceneCollider, scene_meshes
from tohgs.hand.assets import HandAssets
from tohgs.hand.collision import CollisionHand, sd_hand_of
from tohgs.metrics.quality import (DisplacementSimulator, RobustSDSettings, SDSettings, SDWorkers, hand_quality,
                                   sd_gravity, surface_voxels)

log = logging.getLogger(__name__)

COLUMNS = ("task", "method", "object", "config_index", "sample", "pv", "sd", "contact_distance", "init_opp",
           "goal_opp", "ds", "hand_vertices", "kept", "sd_perturbed", "sd_palm")
OPTIONAL_COLUMNS = ("sd_perturbed", "sd_palm")  # metric rows without them read as having none (NaN)
PV_MESHES = ("collision", "mesh")  # the surfaces PV may voxelise (evaluation.pv_mesh)


def diversity(vertices: np.ndarray) -> float:
    """DS of one configuration: the mean over pairs ``i < j`` of ``sum_v |x_i,v - x_j,v|`` for (S, V, 3)
    hand vertices, m (0 for fewer than two hands)."""
    s = len(vertices)
    if s < 2:
        return 0.0
    i, j = np.triu_indices(s, 1)
    return float(np.linalg.norm(vertices[i] - vertices[j], axis=-1).sum(-1).mean())


def occupied_fraction(vertices: np.ndarray, collider: SceneCollider) -> np.ndarray:
    """(B,) the fraction of each hand's (B, V, 3) vertices inside the collider's meshes (OPP)."""
    b, v, _ = vertices.shape
    return (collider.depth_inside(vertices.reshape(-1, 3)).reshape(b, v) > 0).mean(1)


@dataclass
class _ObjectAssets:
    mesh: trimesh.Trimesh
    voxels: np.ndarray  # surface voxels in the mesh frame
    collision: Path
    vertex_mean: np.ndarray


def _object_assets(objects_dir: Path, name: str, pitch: float, cache: dict, cache_dir: str | Path | None = None,
                   pv_mesh: str = "collision") -> _ObjectAssets:
    """The target's mesh, the surface voxels PV counts (of ``pv_mesh``: its convex parts or its mesh),
    its collision file and vertex mean, loaded once per object into ``cache``."""
    if pv_mesh not in PV_MESHES:
        raise ValueError(f"evaluation.pv_mesh must be one of {PV_MESHES}, not {pv_mesh!r}")
    if name not in cache:
        mesh = object_mesh(objects_dir, name)
        surface = collision_mesh(objects_dir, name) if pv_mesh == "collision" else mesh
        cache[name] = _ObjectAssets(mesh, surface_voxels(surface, pitch, cache_dir), objects_dir / name / "collision.obj",
                                    np.asarray(mesh.vertices).mean(0))
    return cache[name]


def grasp_metrics(verts_init: np.ndarray, verts_goal: np.ndarray, faces: np.ndarray, palm_ids: np.ndarray,
                  obj: _ObjectAssets, target_pose: np.ndarray, collider: SceneCollider, pitch: float,
                  sim: DisplacementSimulator, robust: RobustSDSettings | None = None,
                  robust_rngs: list[np.random.Generator] | None = None, palm_sd: bool = False,
                  sd_hand: CollisionHand | None = None) -> dict[str, np.ndarray]:
    """PV, SD, contact distance (:func:`tohgs.metrics.quality.hand_quality`) and both OPPs of S hands of one
    configuration; with ``palm_sd`` also ``"sd_palm"``, (S,) SD with gravity out of each palm, m.

    Args:
        verts_init, verts_goal: (S, V, 3) world-frame hand vertices at the initial / goal pose, m.
        faces: (F, 3) the hand's closed faces.
        palm_ids: vertex ids of the palm's contact candidates (the ``away_from_palm`` gravity).
        obj: the target's mesh, surface voxels, collision file and vertex mean (mesh frame).
        target_pose: the target's initial ``[x, y, z, qx, qy, qz, qw]`` pose.
        collider: the scene without the target.
        pitch: the PV voxel size.
        sim: a simulator of the target (its collision shape and the SD protocol).
        robust, robust_rngs: robust SD's settings and one generator per hand (:func:`grasp_rng`), if any:
            then ``"sd_perturbed"`` (S, K) too (:func:`~tohgs.metrics.quality.hand_quality`).
        palm_sd: also ``"sd_palm"``.
        sd_hand: the collision hand SD, robust SD and palm SD simulate, posed from ``verts_init`` (None: the
            full hand, ``verts_init`` and ``faces``).
    """
    sd_mesh = None if sd_hand is None else (sd_hand.pose(verts_init), sd_hand.faces)
    m = hand_quality(verts_init, faces, palm_ids, obj.mesh, obj.voxels, sim, pitch, target_pose,
                     robust=robust, robust_rngs=robust_rngs, sd_mesh=sd_mesh)
    if palm_sd:
        T = pose_matrix(target_pose)
        centre = T[:3, :3] @ np.asarray(obj.vertex_mean, dtype=np.float64) + T[:3, 3]
        palm = dataclasses.replace(sim.settings, gravity_direction="away_from_palm")  # SD's own choice of gravity
        g = sd_gravity(palm, verts_init[:, palm_ids].mean(1), centre)
        sd_vertices, sd_faces = (verts_init, faces) if sd_mesh is None else sd_mesh
        m["sd_palm"] = sim.displacements(sd_vertices, sd_faces, object_pose=target_pose, gravity=g)
    return {**m, "init_opp": occupied_fraction(verts_init, collider), "goal_opp": occupied_fraction(verts_goal, collider)}


def grasp_rng(seed: int, obj: str, config_index: int, sample: int) -> np.random.Generator:
    """The generator of one grasp's robust-SD perturbations: from the seed and the grasp's identity (its
    object's name, configuration and sample), so the draws do not depend on what else is evaluated."""
    return np.random.default_rng([int(seed), zlib.crc32(obj.encode()), int(config_index), int(sample)])


def evaluate_predictions(prediction_store: str | Path, scene_stores: list[str | Path], objects_dir: str | Path,
                         supports_json: str | Path, hand: HandAssets, sd: dict, voxel_pitch: float = 0.001,
                         cache_dir: str | Path | None = None, progress: bool = False,
                         robust_sd: dict | None = None, palm_sd: bool = False, pv_mesh: str = "collision",
                         threads: int = 1, sd_hand: str | int = "full") -> pd.DataFrame:
    """One row per predicted grasp (columns :data:`COLUMNS`) of one task and method.

    Args:
        prediction_store: the method's predictions (``results/predictions/<task>/<method>.zarr``).
        scene_stores: the scene stores of the task's test objects (``results/scenes/<task>/<object>.zarr``).
        objects_dir: the objects stage's folder (``<name>/mesh.obj``, ``<name>/collision.obj``).
        supports_json: the supports file of the objects stage.
        hand: the assets of the hand the predictions are vectors of (posed with
            :meth:`~tohgs.hand.assets.HandAssets.vertices`, so the job does not import torch).
        sd: a config mapping of :class:`~tohgs.metrics.quality.SDSettings` (the workflow passes
            ``metrics.sd`` with ``evaluation.sd_gravity``'s direction and vector).
        voxel_pitch: PV's voxel size, m.
        cache_dir: cache root of the objects' surface voxels (the prior grasps' stage fills it).
        progress: show a progress bar over configurations.
        robust_sd: a config mapping of :class:`~tohgs.metrics.quality.RobustSDSettings` (None or
            ``perturbations: 0``: no robust SD). Column ``sd_perturbed`` holds each grasp's K perturbed SDs,
            m (an empty list for a grasp without them).
        palm_sd: also column ``sd_palm`` (SD with gravity out of the palm; NaN without).
        pv_mesh: the surface PV voxelises, ``"collision"`` (the paper's protocol) or ``"mesh"``.
        threads: the job's cores: SD runs in that many worker processes, shared by the objects
            (:class:`~tohgs.metrics.quality.SDWorkers`; the same numbers as one).
        sd_hand: the hand SD simulates (``evaluation.sd_hand``): ``"full"`` (its closed faces) or a triangle
            count (:func:`tohgs.hand.collision.sd_hand_of`, cached under ``cache_dir``).
    """
    from tohgs.assets.supports import read_supports

    arrays, attrs = read_predictions(prediction_store)
    s_sd = settings_from(SDSettings, sd)
    robust = settings_from(RobustSDSettings, robust_sd or {})
    scenes = {}
    for p in scene_stores:
        sc = read_scenes(p)
        scenes[sc.object] = sc
    vocab = list(attrs["objects"])
    supports = read_supports(supports_json)
    objects_dir = Path(objects_dir)
    faces = np.asarray(hand.closed_faces)
    collision = sd_hand_of(hand, sd_hand, cache_dir)
    n_vertices = len(hand.rest_vertices)
    assets: dict = {}
    meshes: dict = {}
    rows = []
    it = range(len(arrays["object_id"]))
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"evaluate {attrs['task']}/{attrs['method']}", mininterval=5.0)
    sims: dict[str, DisplacementSimulator] = {}
    workers = SDWorkers(threads)
    try:
        for i in it:
            name = vocab[int(arrays["object_id"][i])]
            if name not in scenes:
                raise ValueError(f"{prediction_store}: configuration {i} is of {name!r}, which has no scene store among "
                                 f"the inputs ({sorted(scenes)})")
            sc, c = scenes[name], int(arrays["config_index"][i])
            if not 0 <= c < len(sc):
                raise ValueError(f"{prediction_store}: configuration index {c} of {name!r} is out of range ({len(sc)})")
            obj = _object_assets(objects_dir, name, voxel_pitch, assets, cache_dir, pv_mesh)
            if name not in sims:
                sims[name] = DisplacementSimulator(obj.collision, obj.vertex_mean, s_sd, workers=workers)
            collider = SceneCollider(scene_meshes(sc, c, objects_dir, supports, meshes))
            kept = np.asarray(arrays["kept"][i], bool)
            m, ds = {}, float("nan")  # DS of a configuration that a filter left fewer than two grasps: none
            if kept.any():
                v_init = hand.vertices(arrays["grasp_init"][i][kept])
                v_goal = hand.vertices(arrays["grasp_goal"][i][kept])
                rngs = [grasp_rng(robust.seed, name, c, k) for k in np.flatnonzero(kept)]
                m = grasp_metrics(v_init, v_goal, faces, hand.palm_ids, obj, sc.target_init_pose[c], collider,
                                  voxel_pitch, sims[name], robust, rngs, palm_sd, collision)
                if kept.all() or kept.sum() >= 2:
                    ds = diversity(v_init)
            at = np.cumsum(kept) - 1  # the row of each kept grasp among the metrics
            perturbed = m.pop("sd_perturbed", None)
            for k in range(len(kept)):
                values = ({key: float(val[at[k]]) for key, val in m.items()} if kept[k] else
                          dict.fromkeys(("pv", "sd", "contact_distance", "init_opp", "goal_opp"), float("nan")))
                values.setdefault("sd_palm", float("nan"))
                sd_k = perturbed[at[k]] if kept[k] and perturbed is not None else np.zeros(0)
                rows.append({"task": attrs["task"], "method": attrs["method"], "object": name, "config_index": c,
                             "sample": k, **values, "ds": ds, "hand_vertices": n_vertices, "kept": bool(kept[k]),
                             "sd_perturbed": [float(x) for x in sd_k if np.isfinite(x)]})
    finally:
        for sim in sims.values():
            sim.close()
        workers.close()
    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    return frame.astype({"config_index": np.int32, "sample": np.int32, "hand_vertices": np.int32, "kept": bool})
