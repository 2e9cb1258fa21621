"""Task-grasp stores: ``results/grasps/task/<task>/<object>.zarr``, the expanded grasps of one target.

Zarr v3, contiguous ragged layout over the scene store's C configurations (K kept grasps in all):

=================  ========  ================  ====================================================
array              shape     dimension_names   meaning
=================  ========  ================  ====================================================
config             (K,)      grasp             the configuration (index into the scene store)
prior_index        (K,)      grasp             the grasp's index in the object's prior store
grasp_init         (K, 51)   grasp, param      the grasp at the target's initial pose, world frame
grasp_goal         (K, 51)   grasp, param      the same hand carried to the goal pose, world frame
kept_per_config    (C,)      config            grasps kept per configuration
=================  ========  ================  ====================================================

Root attributes: ``schema``, ``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``task``, ``object``, ``n_prior_accepted``, ``config``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tohgs.data.store import read_store, write_store

SCHEMA = "tohgs.task_grasps"
SCHEMA_VERSION = 1
_ARRAYS = {"config": (("grasp",), np.int32), "prior_index": (("grasp",), np.int32),
           "grasp_init": (("grasp", "param"), np.float32), "grasp_goal": (("grasp", "param"), np.float32),
           "kept_per_config": (("config",), np.int64)}


def _validate(arrays: dict[str, np.ndarray], source: str) -> None:
    k = len(arrays["config"])
    for name, shape in {"config": (k,), "prior_index": (k,), "grasp_init": (k, 51), "grasp_goal": (k, 51)}.items():
        if arrays[name].shape != shape:
            raise ValueError(f"{source}: array '{name}' has shape {arrays[name].shape}, expected {shape}")
    kept = arrays["kept_per_config"]
    if kept.ndim != 1 or kept.sum() != k:
        raise ValueError(f"{source}: kept_per_config does not add up to the {k} grasps")
    if k and (arrays["config"].min() < 0 or arrays["config"].max() >= len(kept)):
        raise ValueError(f"{source}: config index out of range 0..{len(kept) - 1}")


def write_task_grasps(arrays: dict[str, np.ndarray], attrs: dict[str, Any], path: str | Path) -> None:
    """Write the arrays of :func:`tohgs.grasps.expand.expand_configurations` as a store, atomically."""
    arrays = {k: np.asarray(arrays[k], dtype=dt) for k, (_, dt) in _ARRAYS.items()}
    _validate(arrays, str(path))
    write_store(path, {k: (arrays[k], dims) for k, (dims, _) in _ARRAYS.items()}, attrs, SCHEMA, SCHEMA_VERSION)


def read_task_grasps(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Open and validate a task-grasp store: ``(arrays, attrs)``; ``ValueError`` names the store."""
    arrays, attrs = read_store(path, SCHEMA, SCHEMA_VERSION, list(_ARRAYS), "task-grasp store")
    _validate(arrays, str(path))
    return arrays, attrs
