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
kept            (C, S)        config, sample         False where the method discarded the grasp (a
                                                     filter, F-GraspTTA's); the evaluation skips it
==============  ============  =====================  ==============================================

Root attributes: ``schema``, ``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``task``, ``method``,
``method_config`` (the method's config block), ``objects``, ``components`` (per trained component: its kind
and final training loss), ``config`` (the sampling settings), ``timing`` (seconds per grasp and per stage),
``skipped_configs``, ``discarded`` (grasps not kept) and ``diagnostics`` (per configuration, what the
method records of it: e.g. its adaptation energy or ICP error; lists in the configurations' order). :mod:`tohgs.methods.predict` writes them.
"""

from __future__ import annotations


import numpy as np

from tohgs.data.store import StoreLayout, check_shapes
from tohgs.hand.layout import GRASP_DIM

SCHEMA = "tohgs.predictions"
SCHEMA_VERSION = 2  # 2: kept
_ARRAYS = {"object_id": (("config",), np.int32), "config_index": (("config",), np.int32),
           "contact": (("config", "sample", "point"), np.float32),
           "grasp_init": (("config", "sample", "param"), np.float32),
           "grasp_goal": (("config", "sample", "param"), np.float32),
           "kept": (("config", "sample"), np.bool_)}


def _validate(a: dict[str, np.ndarray], source: str) -> None:
    c = len(a["object_id"])
    s = a["grasp_init"].shape[1] if a["grasp_init"].ndim == 3 else -1
    n = a["contact"].shape[2] if a["contact"].ndim == 3 else -1
    expect = {"object_id": (c,), "config_index": (c,), "contact": (c, s, n), "grasp_init": (c, s, GRASP_DIM),
              "grasp_goal": (c, s, GRASP_DIM), "kept": (c, s)}
    check_shapes(a, expect, source)
    for name in ("grasp_init", "grasp_goal"):  # a NaN goal grasp would score OPP 0 at the goal
        if not np.isfinite(a[name]).all():
            raise ValueError(f"{source}: non-finite grasps in '{name}'")


LAYOUT = StoreLayout(SCHEMA, SCHEMA_VERSION, "prediction store", _ARRAYS, _validate)
write_predictions = LAYOUT.write  # (arrays, attrs, path): cast, check and write the store atomically
read_predictions = LAYOUT.read  # (path) -> (arrays, attrs), checked; ValueError names the store and the problem
