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

Root attributes: ``schema``, ``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``task``, ``object``, ``n_prior_accepted``, ``config``,
and (generated stores) ``rejected_init`` / ``rejected_goal``: per configuration, the accepted prior grasps the
scene rejects at the initial / goal pose (:func:`tohgs.grasps.expand.expand_configurations`).
"""

from __future__ import annotations


import numpy as np

from tohgs.data.store import StoreLayout, check_shapes
from tohgs.hand.layout import GRASP_DIM

SCHEMA = "tohgs.task_grasps"
SCHEMA_VERSION = 1
_ARRAYS = {"config": (("grasp",), np.int32), "prior_index": (("grasp",), np.int32),
           "grasp_init": (("grasp", "param"), np.float32), "grasp_goal": (("grasp", "param"), np.float32),
           "kept_per_config": (("config",), np.int64)}


def _validate(arrays: dict[str, np.ndarray], source: str) -> None:
    k = len(arrays["config"])
    check_shapes(arrays, {"config": (k,), "prior_index": (k,), "grasp_init": (k, GRASP_DIM), "grasp_goal": (k, GRASP_DIM)},
                 source)
    kept = arrays["kept_per_config"]
    if kept.ndim != 1 or kept.sum() != k:
        raise ValueError(f"{source}: kept_per_config does not add up to the {k} grasps")
    if k and (arrays["config"].min() < 0 or arrays["config"].max() >= len(kept)):
        raise ValueError(f"{source}: config index out of range 0..{len(kept) - 1}")


LAYOUT = StoreLayout(SCHEMA, SCHEMA_VERSION, "task-grasp store", _ARRAYS, _validate)
write_task_grasps = LAYOUT.write  # (arrays, attrs, path): cast, check and write the store atomically
read_task_grasps = LAYOUT.read  # (path) -> (arrays, attrs), checked; ValueError names the store and the problem
