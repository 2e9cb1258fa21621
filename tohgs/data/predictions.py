"""Prediction stores: ``results/predictions/<task>/<method>.zarr``, S grasps per test configuration.

Zarr v3; per test configuration ``c`` (C of them, in the test shards' order) and sample ``s`` (S):

==============  ============  =====================  ==============================================
array           shape         dimension_names        meaning
==============  ============  =====================  ==============================================
object_id       (C,)          config                 index into attrs ``objects``
config_index    (C,)          config                 the configuration's index in its scene store
contact         (C, S, N)     config, sample, point  the contact map each grasp was generated from
grasp_init      (C, S, 51)    config, sample, param  grasp at the target's initial pose, world frame
grasp_goal      (C, S, 51)    config, sample, param  the same hand carried to the goal pose, world frame
==============  ============  =====================  ==============================================

Root attributes: ``schema``, ``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``task``, ``method``, ``objects``, ``contact_source``,
``config`` (the sampling settings) and ``timing`` (seconds per grasp and per contact map).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tohgs.data.store import read_store, write_store

SCHEMA = "tohgs.predictions"
SCHEMA_VERSION = 1
_ARRAYS = {"object_id": (("config",), np.int32), "config_index": (("config",), np.int32),
           "contact": (("config", "sample", "point"), np.float32),
           "grasp_init": (("config", "sample", "param"), np.float32),
           "grasp_goal": (("config", "sample", "param"), np.float32)}


def _validate(a: dict[str, np.ndarray], source: str) -> None:
    c = len(a["object_id"])
    s = a["grasp_init"].shape[1] if a["grasp_init"].ndim == 3 else -1
    n = a["contact"].shape[2] if a["contact"].ndim == 3 else -1
    expect = {"object_id": (c,), "config_index": (c,), "contact": (c, s, n), "grasp_init": (c, s, 51),
              "grasp_goal": (c, s, 51)}
    for name, shape in expect.items():
        if a[name].shape != shape:
            raise ValueError(f"{source}: array '{name}' has shape {a[name].shape}, expected {shape}")
    if not np.isfinite(a["grasp_init"]).all():
        raise ValueError(f"{source}: non-finite grasps")


def write_predictions(arrays: dict[str, np.ndarray], attrs: dict[str, Any], path: str | Path) -> None:
    """Write a prediction store atomically."""
    arrays = {k: np.asarray(arrays[k], dtype=dt) for k, (_, dt) in _ARRAYS.items()}
    _validate(arrays, str(path))
    write_store(path, {k: (arrays[k], dims) for k, (dims, _) in _ARRAYS.items()}, attrs, SCHEMA, SCHEMA_VERSION)


def read_predictions(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Open and validate a prediction store: ``(arrays, attrs)``; ``ValueError`` names the store."""
    arrays, attrs = read_store(path, SCHEMA, SCHEMA_VERSION, list(_ARRAYS), "prediction store")
    _validate(arrays, str(path))
    return arrays, attrs


def reference_predictions(test_shards: list[str | Path], task: str, samples: int, seed: int, out: str | Path
                          ) -> dict[str, np.ndarray]:
    """The ``dataset`` reference method: held-out ground-truth task grasps of the test configurations,
    written as a prediction store so that they are evaluated exactly like a method's grasps.

    Per test configuration with at least one ground-truth grasp, ``samples`` of them are drawn without
    replacement (seeded); a configuration with fewer grasps repeats them in turn (its DS is then a lower
    bound). Configurations without any ground-truth grasp are left out. The grasps move from the network
    frame to the world frame (``+ centroid``) and on to the goal pose (``goal_transform``).
    """
    from tohgs.data.maps import read_map_shard
    from tohgs.grasps.expand import transform_grasp

    rng = np.random.default_rng(seed)
    rows = {k: [] for k in _ARRAYS}
    vocab: list[str] = []
    n_points = 0
    for path in test_shards:
        shard = read_map_shard(path)
        if not vocab:
            vocab = list(shard.attrs["objects"])
        elif list(shard.attrs["objects"]) != vocab:
            raise ValueError(f"{path}: its objects vocabulary differs from the first shard's")
        wrist = np.asarray(shard.attrs["hand_wrist"], dtype=np.float64)
        n_points = shard.points.shape[1]
        for c in range(shard.n_configs):
            ids = np.flatnonzero(shard.grasp_config == c)
            if len(ids) == 0:
                continue
            pick = rng.permutation(ids)[np.arange(samples) % len(ids)]
            world = shard.grasp[pick].astype(np.float64)
            world[:, :3] += shard.centroid[c]
            rows["object_id"].append(int(shard.object_id[c]))
            rows["config_index"].append(int(shard.config_index[c]))
            rows["contact"].append(shard.contact[pick])
            rows["grasp_init"].append(world)
            rows["grasp_goal"].append(transform_grasp(world, shard.goal_transform[c], wrist))
    n = len(rows["object_id"])
    arrays = {"object_id": np.asarray(rows["object_id"]), "config_index": np.asarray(rows["config_index"]),
              "contact": np.stack(rows["contact"]) if n else np.zeros((0, samples, n_points)),
              "grasp_init": np.stack(rows["grasp_init"]) if n else np.zeros((0, samples, 51)),
              "grasp_goal": np.stack(rows["grasp_goal"]) if n else np.zeros((0, samples, 51))}
    write_predictions(arrays, {"task": task, "method": "dataset", "objects": vocab, "contact_source": "ground_truth",
                               "config": {"samples": samples, "seed": seed}}, out)
    return arrays
