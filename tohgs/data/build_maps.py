"""Build map shards from scene stores and task grasps (the dataset stage's workhorse).

The configurations of one task and split (all of them for train and validation objects, the first
``test_configs`` of each test object that kept a task grasp: of those the official evaluation uses, for an
official import's Shelving test store) are listed in a fixed order (object name, then configuration) and
dealt round-robin to ``n_shards`` shards, so each shard is one independent job. Per configuration:

- the object cloud: ``n_points`` area-weighted surface samples of the target with normals (drawn once per
  object from the seed and the object's name), placed at the initial pose;
- the scene cloud: support, obstacles and base sampled within ``scene_radius`` of the target's two
  positions (0: everywhere, as the paper) and farthest-point reduced to ``n_scene_points``;
- ``d_init`` / ``d_goal``: the normalised distance from each object point, with the target at its initial
  / goal pose, to the scene cloud;
- per task grasp: the contact map (normalised distance from each object point to the nearest hand vertex)
  and the grasp vector, both in the network frame (:mod:`tohgs.data.maps`).
"""

from __future__ import annotations

import logging
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import trimesh

from tohgs.assets.mesh import object_mesh
from tohgs.data.maps import MapShard, write_map_shard
from tohgs.geometry.grasp import pose_matrix
from tohgs.geometry.maps import (ALPHA_CONTACT, ALPHA_DISTANCE, nearest_distance, normalised_map, sample_surface,
                                 scene_cloud)
from tohgs.geometry.scene import scene_meshes
from tohgs.hand.assets import HandAssets
from tohgs.hand.layout import GRASP_DIM

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MapSettings:
    """Sizes and constants of the maps (see config ``maps``)."""

    n_points: int = 512
    n_scene_points: int = 2048
    alpha_distance: float = ALPHA_DISTANCE
    alpha_contact: float = ALPHA_CONTACT
    max_grasps_per_config: int = 0  # 0 keeps every task grasp
    scene_radius: float = 0.25  # m around the target's two positions; 0 = the whole scene (the paper)


def shard_items(n_configs: dict[str, int | Sequence[int]], split: str, test_configs: int, n_shards: int, shard: int
                ) -> list[tuple[str, int]]:
    """``(object, configuration)`` pairs of shard ``shard`` of ``n_shards`` (round-robin over the sorted list).

    ``n_configs``: per object its number of configurations (all of them are candidates), or the candidate
    configurations' indices in order (an official test store's evaluated ones); a test split takes the first
    ``test_configs`` candidates of each object."""
    if not 0 <= shard < n_shards:
        raise ValueError(f"shard {shard} out of range 0..{n_shards - 1}")
    candidates = {name: range(n) if isinstance(n, int) else list(n) for name, n in n_configs.items()}
    items = [(name, c) for name in sorted(candidates)
             for c in (candidates[name][:test_configs] if split == "test" else candidates[name])]
    return items[shard::n_shards]


def evaluation_candidates(scenes) -> int | list[int]:
    """The configurations of a scene store that a test split may use: those the official evaluation uses
    (attrs ``official.evaluated``: Shelving's every tenth from the 51st) when the store records them, else
    all (the number of configurations)."""
    evaluated = (scenes.attrs.get("official") or {}).get("evaluated")
    if evaluated is None:
        return len(scenes)
    if not evaluated:
        log.warning("%s: the official evaluation uses none of its %d test configurations (range(50, n, 10)); "
                    "all are candidates", scenes.object, len(scenes))
        return len(scenes)
    return [int(c) for c in evaluated]


def with_ground_truth(candidates: int | Sequence[int], kept_per_config: np.ndarray) -> list[int]:
    """The candidate configurations (a count, or indices in order: :func:`evaluation_candidates`) that kept
    at least one task grasp. A test split takes its configurations among these, so that every row of a
    table, the ``Dataset`` row and the ground-truth-contact rows included, serves every test configuration
    (the official test configurations are those of its dataset, which have grasps)."""
    order = range(candidates) if isinstance(candidates, int) else candidates
    return [int(c) for c in order if kept_per_config[c] > 0]


class EmptySplitError(ValueError):
    """A split that trains holds no task grasp (the message has the counts and what to change)."""


def empty_split_message(task: str, split: str, attrs: dict[str, dict], grasps: dict[str, dict[str, np.ndarray]]) -> str:
    """Why a split holds no task grasp: per object the accepted prior grasps, the configurations and the
    task grasps kept, and the settings that raise them (see docs/conventions.md, "When a split has no grasps")."""
    rows = "; ".join(f"{o}: {attrs[o].get('n_prior_accepted', '?')} accepted prior grasps -> "
                     f"{len(grasps[o]['config'])} task grasps over {len(grasps[o]['kept_per_config'])} configurations"
                     for o in sorted(grasps))
    return (f"{task}/{split}: the split's {len(grasps)} objects kept no task grasp, so nothing can train on it "
            f"({rows}). Raise the yield: more prior grasps per object (prior_grasps.synthesis.batch, iterations), "
            "more configurations per object (scenes.n_configs), more objects in the split "
            "(objects.sources, objects.split), or a looser collision tolerance (task_grasps.tolerance); see the "
            "docs/conventions.md, \"When a split has no grasps\"")


def _object_cloud(objects_dir: Path, name: str, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    mesh = object_mesh(objects_dir, name)
    return sample_surface(mesh, n, np.random.default_rng([int(seed), zlib.crc32(name.encode())]))


def make_map_shard(task: str, split: str, shard: int, n_shards: int, scene_stores: list[str | Path],
                   task_grasp_stores: list[str | Path], objects_dir: str | Path, supports_json: str | Path,
                   hand: HandAssets, settings: dict, test_configs: int, seed: int, out: str | Path) -> MapShard:
    """Build and write shard ``shard`` of ``n_shards`` of one task and split.

    Args:
        task, split: the task and the split (``train``, ``val`` or ``test``).
        scene_stores, task_grasp_stores: the scene and task-grasp stores of the split's target objects
            (the same objects; their order does not matter). A test split may have no task-grasp stores at
            all (an official import's test configurations): its shards then hold no grasps.
        objects_dir, supports_json: the objects stage's outputs.
        hand: the hand's assets (contact maps pose it with :meth:`~tohgs.hand.assets.HandAssets.vertices`;
            the job imports no torch).
        settings: a config mapping of :class:`MapSettings`.
        test_configs: configurations per test object.
        seed: the global seed.
        out: the shard to write.

    Raises:
        EmptySplitError: a training split whose objects kept no task grasp at all (every shard of the split
            sees the whole split, so the first of them to run says so, with the counts per object).
    """
    from tohgs.assets.supports import read_supports
    from tohgs.data.scenes import read_scenes
    from tohgs.data.task_grasps import read_task_grasps

    s = MapSettings(**settings)
    objects_dir = Path(objects_dir)
    supports = read_supports(supports_json)
    scenes = {sc.object: sc for sc in map(read_scenes, scene_stores)}
    grasps, grasp_attrs = {}, {}
    for p in task_grasp_stores:
        arrays, attrs = read_task_grasps(p)
        if attrs.get("task") != task:
            raise ValueError(f"{p}: task grasps of {attrs.get('task')!r}, expected {task!r}")
        grasps[attrs["object"]], grasp_attrs[attrs["object"]] = arrays, attrs
    no_truth = split == "test" and not task_grasp_stores
    if no_truth:
        log.info("%s/%s: no task-grasp stores: the test configurations have no ground-truth grasps", task, split)
    elif set(grasps) != set(scenes):
        raise ValueError(f"{task}/{split}: scene stores of {sorted(scenes)} but task grasps of {sorted(grasps)}")
    if split == "train" and scenes and not any(len(g["config"]) for g in grasps.values()):
        raise EmptySplitError(empty_split_message(task, split, grasp_attrs, grasps))
    candidates = {o: evaluation_candidates(sc) if split == "test" else len(sc) for o, sc in scenes.items()}
    if split == "test" and not no_truth:
        for o in sorted(candidates):
            offered = candidates[o]
            candidates[o] = with_ground_truth(offered, grasps[o]["kept_per_config"])
            n = offered if isinstance(offered, int) else len(offered)
            if len(candidates[o]) < min(n, test_configs):
                log.warning("%s/%s %s: %d of its %d candidate configurations kept a task grasp, %d wanted", task,
                            split, o, len(candidates[o]), n, test_configs)
    items = shard_items(candidates, split, test_configs, n_shards, shard)
    vocab = sorted(scenes)
    wrist = np.asarray(hand.rest_joints[0], dtype=np.float64)
    clouds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    mesh_cache: dict[str, trimesh.Trimesh] = {}
    cfg_rows: dict[str, list] = {k: [] for k in ("object_id", "config_index", "points", "normals", "d_init", "d_goal",
                                                  "scene", "scene_normals", "centroid", "goal_transform")}
    g_rows: dict[str, list] = {k: [] for k in ("grasp_config", "grasp_prior_index", "grasp", "contact")}
    try:
        from tqdm import tqdm

        it = tqdm(items, desc=f"maps {task}/{split}/{shard}", mininterval=5.0)
    except ImportError:  # pragma: no cover
        it = items
    for name, c in it:
        sc = scenes[name]
        if name not in clouds:
            clouds[name] = _object_cloud(objects_dir, name, s.n_points, seed)
        pts, nrm = clouds[name]
        T_init, T_goal = pose_matrix(sc.target_init_pose[c]), pose_matrix(sc.target_goal_pose[c])
        p_init = pts @ T_init[:3, :3].T + T_init[:3, 3]
        p_goal = pts @ T_goal[:3, :3].T + T_goal[:3, 3]
        centroid = p_init.mean(0)
        rng = np.random.default_rng([int(seed), zlib.crc32(f"{task}/{name}/{c}".encode())])
        cloud, cloud_normals = scene_cloud(scene_meshes(sc, c, objects_dir, supports, mesh_cache), s.n_scene_points, rng,
                            centres=np.stack([T_init[:3, 3], T_goal[:3, 3]]), radius=s.scene_radius)
        row = len(cfg_rows["object_id"])
        cfg_rows["object_id"].append(vocab.index(name))
        cfg_rows["config_index"].append(c)
        cfg_rows["points"].append(p_init - centroid)
        cfg_rows["normals"].append(nrm @ T_init[:3, :3].T)
        cfg_rows["d_init"].append(normalised_map(nearest_distance(p_init, cloud), s.alpha_distance))
        cfg_rows["d_goal"].append(normalised_map(nearest_distance(p_goal, cloud), s.alpha_distance))
        cfg_rows["scene"].append(cloud - centroid)
        cfg_rows["scene_normals"].append(cloud_normals)
        cfg_rows["centroid"].append(centroid)
        cfg_rows["goal_transform"].append(T_goal @ np.linalg.inv(T_init))
        g = grasps.get(name)
        sel = np.flatnonzero(g["config"] == c) if g is not None else np.zeros(0, np.int64)
        if s.max_grasps_per_config > 0:
            sel = sel[: s.max_grasps_per_config]
        if len(sel):
            world = g["grasp_init"][sel].astype(np.float64)
            hv = hand.vertices(world)  # (K, V, 3)
            for j, k in enumerate(sel):
                g_rows["contact"].append(normalised_map(nearest_distance(p_init, hv[j]), s.alpha_contact))
            local = world.copy()
            local[:, :3] -= centroid  # a pure translation of the frame: only the grasp's translation moves
            g_rows["grasp"].append(local)
            g_rows["grasp_config"] += [row] * len(sel)
            g_rows["grasp_prior_index"] += g["prior_index"][sel].tolist()
    n, ns = s.n_points, s.n_scene_points

    def stack(rows: list, shape: tuple[int, ...], dtype) -> np.ndarray:
        return np.stack(rows).astype(dtype) if rows else np.zeros((0, *shape), dtype)

    arrays = {
        "object_id": np.asarray(cfg_rows["object_id"], np.int32), "config_index": np.asarray(cfg_rows["config_index"], np.int32),
        "points": stack(cfg_rows["points"], (n, 3), np.float32), "normals": stack(cfg_rows["normals"], (n, 3), np.float32),
        "d_init": stack(cfg_rows["d_init"], (n,), np.float32), "d_goal": stack(cfg_rows["d_goal"], (n,), np.float32),
        "scene": stack(cfg_rows["scene"], (ns, 3), np.float32),
        "scene_normals": stack(cfg_rows["scene_normals"], (ns, 3), np.float32), "centroid": stack(cfg_rows["centroid"], (3,), np.float64),
        "goal_transform": stack(cfg_rows["goal_transform"], (4, 4), np.float64),
        "grasp_config": np.asarray(g_rows["grasp_config"], np.int32),
        "grasp_prior_index": np.asarray(g_rows["grasp_prior_index"], np.int32),
        "grasp": np.concatenate(g_rows["grasp"]).astype(np.float32) if g_rows["grasp"] else np.zeros((0, GRASP_DIM), np.float32),
        "contact": stack(g_rows["contact"], (n,), np.float32),
    }
    shard_data = MapShard(arrays, {"task": task, "split": split, "shard": shard, "n_shards": n_shards, "objects": vocab,
                                   "hand_wrist": wrist.tolist(), "alpha_distance": s.alpha_distance,
                                   "alpha_contact": s.alpha_contact, "seed": int(seed),
                                   "config": {**asdict(s), "test_configs": test_configs}})
    write_map_shard(shard_data, out)
    log.info("%s/%s shard %d of %d: %d configurations, %d grasps", task, split, shard, n_shards,
             shard_data.n_configs, shard_data.n_grasps)
    return shard_data


PAPER_TASK_GRASPS = 1_380_000  # the paper's task grasps over the three tasks (its section 3)


def _size_on_disk(path: Path) -> int:
    return sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())


DIFFICULTY_COLUMNS = ("prior_accepted", "rejected", "rejected_init", "rejected_goal", "obstacle_configs",
                      "gap_init_median", "gap_goal_median")


def scene_difficulty(task_grasp_stores: list[str | Path], scene_stores: list[str | Path], objects_dir: str | Path,
                     n_points: int = 512, seed: int = 0) -> dict[str, dict[str, float]]:
    """How hard each task's scenes are, whatever method runs on them: per task (keys of the result)

    - ``prior_accepted``: accepted prior grasps per target object (mean; NaN for imported stores, which do
      not record it, and so are ``rejected``, ``rejected_init`` and ``rejected_goal``);
    - ``rejected``, ``rejected_init``, ``rejected_goal``: the share of an object's accepted prior grasps the
      scene rejects at either pose, at the initial, at the goal pose (means over configurations; the last
      two NaN for an imported store, which does not record them);
    - ``obstacle_configs``: the share of configurations with obstacles;
    - ``gap_init_median``, ``gap_goal_median``: the median over those of the gap between the target and its
      nearest obstacle at the initial / goal pose, m (:func:`tohgs.geometry.scene.obstacle_gaps`; the
      target's surface at ``n_points`` points drawn from ``seed`` and its name).
    """
    from tohgs.data.scenes import read_scenes
    from tohgs.data.task_grasps import read_task_grasps
    from tohgs.geometry.scene import obstacle_gaps

    scenes = {}
    for p in scene_stores:
        sc = read_scenes(p)
        scenes[(sc.task, sc.object)] = sc
    per_task: dict[str, dict[str, list]] = {}
    meshes: dict[str, trimesh.Trimesh] = {}
    for p in task_grasp_stores:
        arrays, attrs = read_task_grasps(p)
        task, name = attrs["task"], attrs["object"]
        t = per_task.setdefault(task, {k: [] for k in ("accepted", "rejected", "init", "goal", "has", "gap_init", "gap_goal")})
        recorded = attrs.get("n_prior_accepted")  # None for an imported store: its prior grasps are not known
        accepted = int(recorded) if recorded is not None else 0
        t["accepted"].append(float(accepted) if recorded is not None else np.nan)
        kept = arrays["kept_per_config"].astype(np.float64)
        if accepted > 0:
            t["rejected"] += (1 - kept / accepted).tolist()
            for key, pose in (("init", "rejected_init"), ("goal", "rejected_goal")):
                values = attrs.get(pose)
                t[key] += (np.asarray(values, np.float64) / accepted).tolist() if values is not None else [np.nan] * len(kept)
        sc = scenes.get((task, name))
        if sc is None:
            continue
        pts, _ = _object_cloud(Path(objects_dir), name, n_points, seed)
        for c in range(len(sc)):
            gi, gg = obstacle_gaps(sc, c, objects_dir, pts, meshes)
            t["has"].append(float(np.isfinite(gi)))
            if np.isfinite(gi):
                t["gap_init"].append(gi)
                t["gap_goal"].append(gg)

    def mean(v: list) -> float:
        v = np.asarray(v, np.float64)
        return float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")

    def median(v: list) -> float:
        return float(np.median(v)) if v else float("nan")

    return {task: {"prior_accepted": mean(t["accepted"]), "rejected": mean(t["rejected"]),
                   "rejected_init": mean(t["init"]), "rejected_goal": mean(t["goal"]),
                   "obstacle_configs": mean(t["has"]), "gap_init_median": median(t["gap_init"]),
                   "gap_goal_median": median(t["gap_goal"])}
            for task, t in sorted(per_task.items())}


def summarize_dataset(task_grasp_stores: list[str | Path], shards: list[str | Path], out_csv: str | Path,
                      paper_points: int = 2048, paper_scene_points: int = 6000,
                      scene_stores: list[str | Path] = (), objects_dir: str | Path | None = None, seed: int = 0):
    """One row per task and split (shards, configurations, grasps, bytes on disk) plus a row per task of the
    task grasps with its scene difficulty (:func:`scene_difficulty`, :data:`DIFFICULTY_COLUMNS`; the gaps
    need the ``scene_stores`` and the ``objects_dir``); logs the paper-scale size estimate. Returns the
    table (``pandas.DataFrame``)."""
    import pandas as pd

    from tohgs.data.maps import read_map_shard
    from tohgs.data.task_grasps import read_task_grasps
    from tohgs.io import atomic_path

    rows = []
    per_task: dict[str, dict[str, int]] = {}
    for p in task_grasp_stores:
        arrays, attrs = read_task_grasps(p)
        t = per_task.setdefault(attrs["task"], {"objects": 0, "configs": 0, "empty_configs": 0, "grasps": 0, "bytes": 0})
        t["objects"] += 1
        t["configs"] += len(arrays["kept_per_config"])
        t["empty_configs"] += int((arrays["kept_per_config"] == 0).sum())
        t["grasps"] += len(arrays["config"])
        t["bytes"] += _size_on_disk(Path(p))
    difficulty = scene_difficulty(task_grasp_stores, list(scene_stores) if objects_dir is not None else [],
                                  objects_dir or ".", seed=seed)
    for task, t in sorted(per_task.items()):
        d = difficulty.get(task, {})
        rows.append({"task": task, "split": "task_grasps", "shards": 0, **t, **d})
        log.info("%s: %d task grasps over %d configurations of %d objects (%d configurations kept none)", task,
                 t["grasps"], t["configs"], t["objects"], t["empty_configs"])
        if d:
            log.info("%s scene difficulty: the scene rejects %.1f %% of an object's %.0f accepted prior grasps at "
                     "either pose (%.1f %% at the initial, %.1f %% at the goal pose); obstacles in %.0f %% of the "
                     "configurations, median gap to the nearest %.1f / %.1f mm (initial / goal)", task,
                     100 * d["rejected"], d["prior_accepted"], 100 * d["rejected_init"], 100 * d["rejected_goal"],
                     100 * d["obstacle_configs"], 1000 * d["gap_init_median"], 1000 * d["gap_goal_median"])
    grouped: dict[tuple[str, str], dict[str, int]] = {}
    for p in shards:
        sh = read_map_shard(p)
        key = (sh.attrs["task"], sh.attrs["split"])
        g = grouped.setdefault(key, {"objects": 0, "configs": 0, "empty_configs": 0, "grasps": 0, "bytes": 0, "shards": 0})
        g["shards"] += 1
        g["configs"] += sh.n_configs
        g["grasps"] += sh.n_grasps
        g["objects"] = max(g["objects"], len(set(sh.object_id.tolist())))
        size = _size_on_disk(Path(p))
        g["bytes"] += size
    for (task, split), g in sorted(grouped.items()):
        rows.append({"task": task, "split": split, **g})
        log.info("maps %s/%s: %d shards, %d configurations, %d grasps, %.1f MB on disk", task, split, g["shards"],
                 g["configs"], g["grasps"], g["bytes"] / 1e6)
    df = pd.DataFrame(rows, columns=["task", "split", "shards", "objects", "configs", "empty_configs", "grasps", "bytes",
                                     *DIFFICULTY_COLUMNS])
    with atomic_path(out_csv) as tmp:
        df.to_csv(tmp, index=False)
    # Paper scale, uncompressed: every task grasp with a 2048-point contact map and its grasp vector, and
    # per configuration the clouds and distance maps (about 1.38 M grasps; configurations ~ grasps / 30).
    raw_grasp = (paper_points + GRASP_DIM) * 4 + 8
    raw_config = (7 * paper_points + 3 * paper_scene_points) * 4 + 19 * 8 + 8
    est = PAPER_TASK_GRASPS * raw_grasp + PAPER_TASK_GRASPS / 30 * raw_config
    total_bytes = int(df[df.split != "task_grasps"].bytes.sum())
    log.info("maps on disk: %.1f MB; paper scale (1.38 M grasps, 2048 / 6000 points) uncompressed: %.1f GB",
             total_bytes / 1e6, est / 1e9)
    return df
