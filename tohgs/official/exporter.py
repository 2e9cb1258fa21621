"""The exporter of tohgs's predictions into the official TOHGS evaluation's output format.

**The exporter** (:func:`export_official`) writes a prediction store as ``<run_dir>/<obj>.npy`` files of the
official evaluation: a pickled dict with per grasp ``init_hand_vertex`` and ``goal_hand_vertex`` ((V, 3)
float32, metres, official world frame; V is the hand model's vertex count: 778 for MANO, 1609 for the
default anny hand), ``init_pose``, ``goal_pose``, and per task the obstacles, shelf and grasped object.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.data.predictions import read_predictions
from tohgs.data.scenes import read_scenes
from tohgs.hand.assets import HandAssets
from tohgs.io import atomic_path
from tohgs.official.format import TABLE_HEIGHT, shift_grasp, to_official_pose

log = logging.getLogger(__name__)


def export_official(predictions: str | Path, scenes_dir: str | Path, hand: HandAssets, run_dir: str | Path,
                    default_table_top: float = TABLE_HEIGHT) -> dict[str, Path]:
    """Write a prediction store in the official evaluation's output format, ``<run_dir>/<obj>.npy``.

    Each file is ``np.save`` of a dict (numpy arrays, lists, strings only), one entry per kept grasp, in the
    order of the official configurations and then the samples (the official evaluation's order):

    - ``init_hand_vertex``, ``goal_hand_vertex``: (V, 3) float32, metres, the official world frame: the
      vertices of ``hand`` posed by the grasp (V = ``len(hand.rest_vertices)``: 778 for MANO, 1609 for anny;
      the official evaluation scripts expect MANO's 778).
    - ``init_pose``, ``goal_pose``: the target's official pose (7 floats), or for Stacking
      ``[base_name, base_pose, grasped_name, grasped_pose]`` (the base at its one stored pose in both).
    - Placing and Shelving: ``obstacle_name``, ``obstacle_pose`` (lists per grasp) and ``grasped_obj``
      (the target's official name); Shelving also ``shelf_name`` and ``shelf_pose``.
    - Added by tohgs (the official readers ignore them): ``init_recon_param``, ``goal_recon_param``
      ((51,) float32 grasps in the official frame), ``config`` (the official configuration index),
      ``sample``, ``hand_model`` and ``n_hand_vertices``.

    Args:
        predictions: a prediction store (:mod:`tohgs.data.predictions`).
        scenes_dir: the scene stores its ``config_index`` refers to (``<scenes_dir>/<task>/<object>.zarr``):
            the importer's ``test_scenes``, or tohgs's own ``results/scenes``.
        hand: the hand that poses the grasps (the one that made them).
        run_dir: the output folder (the official ``result/<run>``).
        default_table_top: the official table top for scene stores that were not imported (tohgs's own:
            object names and mesh frames are then kept as they are).

    Returns:
        ``{file stem: path}`` of the files written. A file is named after the official file its
        configurations came from (``test/<obj>.json`` -> ``<obj>.npy``), else after the tohgs object.

    Raises:
        ValueError: a store that cannot be read, or a configuration index outside its scene store.
    """
    arrays, attrs = read_predictions(predictions)
    task, objects = attrs["task"], list(attrs["objects"])
    run_dir = Path(run_dir)
    files: dict[str, list[tuple[tuple[int, int], dict[str, Any]]]] = {}
    grasped: dict[str, str] = {}
    for oid in np.unique(arrays["object_id"]):
        path = Path(scenes_dir) / task / f"{objects[oid]}.zarr"
        scenes = read_scenes(path)
        off = scenes.attrs.get("official") or {}
        top = float(off.get("table_top", default_table_top))
        names, offsets, snames = off.get("names", {}), off.get("offsets", {}), off.get("supports", {})
        stem = Path(off["file"]).stem if off.get("file") else scenes.object
        index = off.get("index") or list(range(len(scenes)))

        def official(name: str, pose: np.ndarray, top: float = top, names: dict = names, offsets: dict = offsets
                     ) -> tuple[str, list[float]]:
            return names.get(name, name), to_official_pose(pose, offsets.get(name), top).tolist()

        target = names.get(scenes.object, scenes.object)
        grasped[stem] = target
        for r in np.flatnonzero(arrays["object_id"] == oid):
            c = int(arrays["config_index"][r])
            if not 0 <= c < len(scenes):
                raise ValueError(f"{predictions}: configuration {c} of '{scenes.object}' is outside {path} "
                                 f"({len(scenes)} configurations)")
            keep = np.flatnonzero(arrays["kept"][r])
            g_init = shift_grasp(arrays["grasp_init"][r, keep], top)
            g_goal = shift_grasp(arrays["grasp_goal"][r, keep], top)
            v_init = hand.vertices(g_init).astype(np.float32)
            v_goal = hand.vertices(g_goal).astype(np.float32)
            _, init = official(scenes.object, scenes.target_init_pose[c])
            _, goal = official(scenes.object, scenes.target_goal_pose[c])
            base = scenes.base(c)
            for k, s in enumerate(keep):
                e: dict[str, Any] = {"init_hand_vertex": v_init[k], "goal_hand_vertex": v_goal[k],
                                     "init_recon_param": g_init[k].astype(np.float32),
                                     "goal_recon_param": g_goal[k].astype(np.float32),
                                     "config": int(index[c]), "sample": int(s)}
                if task == "stacking":
                    b = official(*base) if base is not None else ("", [float("nan")] * 7)
                    e["init_pose"], e["goal_pose"] = [b[0], b[1], target, init], [b[0], b[1], target, goal]
                else:
                    e["init_pose"], e["goal_pose"] = init, goal
                    obs = [official(n, p) for n, p in scenes.obstacles(c)]
                    e["obstacle_name"], e["obstacle_pose"] = [n for n, _ in obs], [p for _, p in obs]
                if task == "shelving":
                    sname, spose = scenes.support(c)
                    e["shelf_name"] = snames.get(sname, sname)
                    e["shelf_pose"] = to_official_pose(spose, None, top).tolist()
                files.setdefault(stem, []).append(((int(index[c]), int(s)), e))
    written = {}
    for stem, entries in files.items():
        entries.sort(key=lambda x: x[0])
        keys = list(entries[0][1]) if entries else []
        output: dict[str, Any] = {k: [e[k] for _, e in entries] for k in keys}
        if task != "stacking":
            output["grasped_obj"] = grasped[stem]
        output.update(hand_model=hand.name, n_hand_vertices=int(len(hand.rest_vertices)))
        path = run_dir / f"{stem}.npy"
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.save(fh, np.array(output, dtype=object), allow_pickle=True)
        written[stem] = path
    log.info("official export: %d files, %d grasps into %s", len(written), sum(len(v) for v in files.values()), run_dir)
    return written

