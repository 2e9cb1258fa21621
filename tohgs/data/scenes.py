"""Scene stores: ``results/scenes/<task>/<object>.zarr``, one per task and target object.

Zarr v3, contiguous ragged layout (DESIGN.md): per configuration ``c`` (C of them)

====================  ============  ==================  =============================================
array                 shape         dimension_names     meaning
====================  ============  ==================  =============================================
target_init_pose      (C, 7)        config, pose        settled pose of the target where it is picked
target_goal_pose      (C, 7)        config, pose        settled pose of the target where it is put
support_id            (C,)          config              index into attrs ``supports`` (table, shelf-*)
support_pose          (C, 7)        config, pose        pose of the support
base_id               (C,)          config              index into attrs ``objects``; -1 = no base
base_pose             (C, 7)        config, pose        pose of the base brick (NaN without one)
obstacle_offsets      (C + 1,)      config_edge         obstacles of config c: [offsets[c], offsets[c+1])
obstacle_id           (O,)          obstacle            index into attrs ``objects``
obstacle_pose         (O, 7)        obstacle, pose      settled obstacle poses (the same in both scenes)
====================  ============  ==================  =============================================

Poses are ``[x, y, z, qx, qy, qz, qw]`` (metres, scipy's xyzw quaternion order) of each object's mesh
frame. Root attributes: ``schema``, ``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``task``, ``object``, ``seed``, ``config`` (the
settings that made it), ``objects`` and ``supports`` (the vocabularies), ``n_requested``, ``tries`` and
``rejections`` (counts by reason).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.data.store import read_store, write_store

SCHEMA = "tohgs.scenes"
SCHEMA_VERSION = 1

_ARRAYS = {
    "target_init_pose": (("config", "pose"), np.float64),
    "target_goal_pose": (("config", "pose"), np.float64),
    "support_id": (("config",), np.int32),
    "support_pose": (("config", "pose"), np.float64),
    "base_id": (("config",), np.int32),
    "base_pose": (("config", "pose"), np.float64),
    "obstacle_offsets": (("config_edge",), np.int64),
    "obstacle_id": (("obstacle",), np.int32),
    "obstacle_pose": (("obstacle", "pose"), np.float64),
}


@dataclass
class SceneSet:
    """The configurations of one task and target object (arrays as in the module table)."""

    task: str
    object: str
    target_init_pose: np.ndarray
    target_goal_pose: np.ndarray
    support_id: np.ndarray
    support_pose: np.ndarray
    base_id: np.ndarray
    base_pose: np.ndarray
    obstacle_offsets: np.ndarray
    obstacle_id: np.ndarray
    obstacle_pose: np.ndarray
    objects: list[str]
    supports: list[str]
    attrs: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.target_init_pose)

    def obstacles(self, c: int) -> list[tuple[str, np.ndarray]]:
        """``(object name, pose)`` of configuration ``c``'s obstacles."""
        a, b = self.obstacle_offsets[c], self.obstacle_offsets[c + 1]
        return [(self.objects[i], p) for i, p in zip(self.obstacle_id[a:b], self.obstacle_pose[a:b])]

    def base(self, c: int) -> tuple[str, np.ndarray] | None:
        i = int(self.base_id[c])
        return None if i < 0 else (self.objects[i], self.base_pose[c])

    def support(self, c: int) -> tuple[str, np.ndarray]:
        return self.supports[int(self.support_id[c])], self.support_pose[c]

    def validate(self, source: str = "scene set") -> None:
        """Check shapes, dtypes, offsets and indices; raises ``ValueError`` naming ``source``."""
        c = len(self.target_init_pose)
        o = len(self.obstacle_id)
        expect = {"target_init_pose": (c, 7), "target_goal_pose": (c, 7), "support_id": (c,), "support_pose": (c, 7),
                  "base_id": (c,), "base_pose": (c, 7), "obstacle_offsets": (c + 1,), "obstacle_id": (o,),
                  "obstacle_pose": (o, 7)}
        for name, shape in expect.items():
            arr = getattr(self, name)
            if arr.shape != shape:
                raise ValueError(f"{source}: array '{name}' has shape {arr.shape}, expected {shape}")
            if arr.dtype != _ARRAYS[name][1]:
                raise ValueError(f"{source}: array '{name}' has dtype {arr.dtype}, expected {np.dtype(_ARRAYS[name][1])}")
        off = self.obstacle_offsets
        if off[0] != 0 or off[-1] != o or np.any(np.diff(off) < 0):
            raise ValueError(f"{source}: obstacle_offsets are not a non-decreasing 0..{o} partition")
        if len(self.obstacle_id) and (self.obstacle_id.min() < 0 or self.obstacle_id.max() >= len(self.objects)):
            raise ValueError(f"{source}: obstacle_id out of range of the objects vocabulary")
        if c and (self.support_id.min() < 0 or self.support_id.max() >= len(self.supports)):
            raise ValueError(f"{source}: support_id out of range of the supports vocabulary")
        for name in ("target_init_pose", "target_goal_pose", "obstacle_pose", "support_pose"):
            q = getattr(self, name)[:, 3:]
            if len(q) and not np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5):
                raise ValueError(f"{source}: '{name}' holds non-unit quaternions")


def write_scenes(scenes: SceneSet, path: str | Path) -> None:
    """Write a :class:`SceneSet` as a Zarr v3 store, atomically (temporary folder, then rename)."""
    scenes.validate(str(path))
    arrays = {name: (np.asarray(getattr(scenes, name), dtype=dtype), dims) for name, (dims, dtype) in _ARRAYS.items()}
    attrs = {k: v for k, v in scenes.attrs.items() if k not in ("task", "object", "objects", "supports")}
    write_store(path, arrays, {**attrs, "task": scenes.task, "object": scenes.object, "objects": list(scenes.objects),
                               "supports": list(scenes.supports)}, SCHEMA, SCHEMA_VERSION)


def read_scenes(path: str | Path) -> SceneSet:
    """Open and validate a scene store.

    Raises:
        ValueError: not a tohgs scene store, a wrong schema version, missing or damaged arrays or
            inconsistent contents (the message names the store and the problem).
    """
    arrays, attrs = read_store(path, SCHEMA, SCHEMA_VERSION, list(_ARRAYS), "scene store",
                               dims={name: dims for name, (dims, _) in _ARRAYS.items()})
    scenes = SceneSet(task=attrs["task"], object=attrs["object"], objects=list(attrs["objects"]),
                      supports=list(attrs["supports"]), attrs=attrs, **arrays)
    scenes.validate(str(path))
    return scenes
