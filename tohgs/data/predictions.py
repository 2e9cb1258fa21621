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

Root attributes: ``schema``, ``schema_version``, ``task``, ``method``, ``objects``, ``contact_source``,
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
