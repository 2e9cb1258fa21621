"""Map shards: ``results/maps/<task>/<split>/shard-<k>.zarr``, the networks' training and test data.

Zarr v3 with the sharding codec (inner chunks of ``CHUNK`` rows inside one shard file per array). Per
configuration ``c`` (C in the shard) and per task grasp ``g`` (G; none in a test shard without
ground-truth grasps), all coordinates in the *network frame*: the world frame translated so that the
object cloud's centroid at the initial pose is the origin (no rotation, so "up" stays up).

=================  ============  ====================  ===============================================
array              shape         dimension_names       meaning
=================  ============  ====================  ===============================================
object_id          (C,)          config                index into attrs ``objects``
config_index       (C,)          config                the configuration's index in its scene store
points             (C, N, 3)     config, point, xyz    object surface points at the initial pose, m
normals            (C, N, 3)     config, point, xyz    their outward unit normals
d_init, d_goal     (C, N)        config, point         distance maps (alpha 30) in the initial / goal scene
scene              (C, Ns, 3)    config, scene_point,  scene cloud: support, obstacles and base, never the
                                 xyz                   target (the same in the initial and goal scene), m
scene_normals      (C, Ns, 3)    config, scene_point,  the scene points' outward unit normals (the faces
                                 xyz                   they were sampled on)
centroid           (C, 3)        config, xyz           world position of the network frame's origin, m
goal_transform     (C, 4, 4)     config, row, col      T_goal T_init^-1: carries the target (and a hand
                                                       holding it) from its initial to its goal pose
grasp_config       (G,)          grasp                 row of the grasp's configuration in this shard
grasp_prior_index  (G,)          grasp                 the grasp's index in the object's prior store
grasp              (G, 51)       grasp, param          the grasp at the initial pose, network frame
contact            (G, N)        grasp, point          contact map (alpha 100) of the grasp's hand
=================  ============  ====================  ===============================================

``goal_transform`` is a world-frame transform; in the network frame it is ``S T S^-1`` with ``S`` the
translation by ``-centroid`` (:func:`network_goal_transform`). Root attributes: ``schema``,
``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``task``, ``split``, ``shard``, ``n_shards``, ``objects``, ``hand_wrist`` (the hand's
rest wrist joint, needed to rotate grasp vectors), ``alpha_distance``, ``alpha_contact``, ``seed`` and
``config``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.data.store import check_shapes, read_store, write_store
from tohgs.hand.layout import GRASP_DIM

SCHEMA = "tohgs.maps"
SCHEMA_VERSION = 2  # 2: scene_normals
CHUNK = 64

# name: (dimension names, dtype, "config" | "grasp")
ARRAYS: dict[str, tuple[tuple[str, ...], type, str]] = {
    "object_id": (("config",), np.int32, "config"),
    "config_index": (("config",), np.int32, "config"),
    "points": (("config", "point", "xyz"), np.float32, "config"),
    "normals": (("config", "point", "xyz"), np.float32, "config"),
    "d_init": (("config", "point"), np.float32, "config"),
    "d_goal": (("config", "point"), np.float32, "config"),
    "scene": (("config", "scene_point", "xyz"), np.float32, "config"),
    "scene_normals": (("config", "scene_point", "xyz"), np.float32, "config"),
    "centroid": (("config", "xyz"), np.float64, "config"),
    "goal_transform": (("config", "row", "col"), np.float64, "config"),
    "grasp_config": (("grasp",), np.int32, "grasp"),
    "grasp_prior_index": (("grasp",), np.int32, "grasp"),
    "grasp": (("grasp", "param"), np.float32, "grasp"),
    "contact": (("grasp", "point"), np.float32, "grasp"),
}


@dataclass
class MapShard:
    """The contents of one shard (arrays as in the module table)."""

    arrays: dict[str, np.ndarray]
    attrs: dict[str, Any] = field(default_factory=dict)
    source: str = "map shard"  # where it was read from, for the errors

    @property
    def alpha_contact(self) -> float:
        """The alpha (1/m) of the shard's contact maps (its ``alpha_contact`` attribute): what a method or a
        component compares its own hands' maps with.

        Raises:
            ValueError: the shard does not record it (named).
        """
        return float(self._attr("alpha_contact"))

    @property
    def alpha_distance(self) -> float:
        """The alpha (1/m) of the shard's distance maps (its ``alpha_distance`` attribute).

        Raises:
            ValueError: the shard does not record it (named).
        """
        return float(self._attr("alpha_distance"))

    def _attr(self, key: str) -> Any:
        if key not in self.attrs:
            raise ValueError(f"{self.source}: the attribute '{key}' is missing (a map shard written by "
                             "tohgs.data.build_maps records it); rebuild the shard")
        return self.attrs[key]

    @property
    def n_configs(self) -> int:
        return len(self.arrays["object_id"])

    @property
    def n_grasps(self) -> int:
        return len(self.arrays["grasp"])

    def __getattr__(self, name: str) -> np.ndarray:
        arrays = self.__dict__.get("arrays", {})
        if name in arrays:
            return arrays[name]
        raise AttributeError(name)

    def validate(self, source: str = "map shard") -> None:
        """Check presence, dtypes, shapes and indices; raises ``ValueError`` naming ``source``."""
        a = self.arrays
        missing = set(ARRAYS) - set(a)
        if missing:
            raise ValueError(f"{source}: missing arrays {sorted(missing)}")
        c, g = len(a["object_id"]), len(a["grasp"])
        n, ns = a["points"].shape[1], a["scene"].shape[1]
        expect = {"object_id": (c,), "config_index": (c,), "points": (c, n, 3), "normals": (c, n, 3), "d_init": (c, n),
                  "d_goal": (c, n), "scene": (c, ns, 3), "scene_normals": (c, ns, 3), "centroid": (c, 3),
                  "goal_transform": (c, 4, 4), "grasp_config": (g,), "grasp_prior_index": (g,), "grasp": (g, GRASP_DIM),
                  "contact": (g, n)}
        check_shapes(a, expect, source)
        for name in expect:
            if a[name].dtype != ARRAYS[name][1]:
                raise ValueError(f"{source}: array '{name}' has dtype {a[name].dtype}, expected {np.dtype(ARRAYS[name][1])}")
        if g and (a["grasp_config"].min() < 0 or a["grasp_config"].max() >= c):
            raise ValueError(f"{source}: grasp_config out of range 0..{c - 1}")
        objects = self.attrs.get("objects", [])
        if c and (a["object_id"].min() < 0 or a["object_id"].max() >= len(objects)):
            raise ValueError(f"{source}: object_id out of range of the objects vocabulary")
        for name in ("d_init", "d_goal", "contact"):
            v = a[name]
            if v.size and not (np.isfinite(v).all() and v.min() >= 0 and v.max() <= 1):
                raise ValueError(f"{source}: '{name}' is not a map in [0, 1]")


def write_map_shard(shard: MapShard, path: str | Path) -> None:
    """Write a :class:`MapShard` as a sharded Zarr v3 store, atomically."""
    shard.validate(str(path))
    arrays = {name: (np.asarray(shard.arrays[name], dtype=dtype), dims) for name, (dims, dtype, _) in ARRAYS.items()}
    write_store(path, arrays, shard.attrs, SCHEMA, SCHEMA_VERSION, shard_rows=CHUNK)


def read_map_shard(path: str | Path) -> MapShard:
    """Open and validate a map shard.

    Raises:
        ValueError: not a tohgs map shard, a wrong schema version, a missing, truncated or inconsistent array
            (the message names the shard and the problem).
    """
    arrays, attrs = read_store(path, SCHEMA, SCHEMA_VERSION, list(ARRAYS), "map shard")
    shard = MapShard(arrays, attrs, str(path))
    shard.validate(str(path))
    return shard


def network_goal_transform(goal_transform: np.ndarray, centroid: np.ndarray) -> np.ndarray:
    """(..., 4, 4) ``T_goal T_init^-1`` expressed in the network frame (origin at ``centroid``)."""
    S = np.broadcast_to(np.eye(4), goal_transform.shape).copy()
    S[..., :3, 3] = -np.asarray(centroid)
    S_inv = S.copy()
    S_inv[..., :3, 3] = np.asarray(centroid)
    return S @ goal_transform @ S_inv


ROTATIONS = ("so3", "z", "bounded", "none")


def random_rotation(generator: np.random.Generator, mode: str, max_angle: float = np.pi / 6) -> np.ndarray:
    """(3, 3) a uniformly random rotation (``"so3"``), about z only (``"z"``), about a uniformly random axis
    by an angle uniform in [0, ``max_angle``] rad (``"bounded"``: small turns of the initial pose, as
    ContactGen trains), or the identity (``"none"``)."""
    if mode == "none":
        return np.eye(3)
    if mode == "bounded":
        axis = generator.normal(size=3)
        angle = generator.uniform(0.0, max_angle)
        from scipy.spatial.transform import Rotation

        return Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
    if mode == "z":
        a = generator.uniform(0, 2 * np.pi)
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if mode == "so3":
        q = generator.normal(size=4)
        q /= np.linalg.norm(q)
        from scipy.spatial.transform import Rotation

        return Rotation.from_quat(q).as_matrix()
    raise ValueError(f"rotation mode must be one of {ROTATIONS}, not {mode!r}")


class MapDataset:
    """A torch-style map dataset over shards: one item per task grasp (``per="grasp"``, training) or per
    configuration (``per="config"``, testing).

    Items are dicts of float32 numpy arrays: ``points`` (N, 3), ``normals`` (N, 3), ``d_init``, ``d_goal``
    (N,), ``scene`` (Ns, 3), ``goal_transform`` (4, 4, network frame), ``object_id``, ``config_index``, ``shard`` and ``row``
    (ints), plus ``grasp`` (51,) and ``contact`` (N,) per grasp. With ``rotation`` other than ``"none"``
    (:func:`random_rotation`; ``"bounded"`` turns by at most ``rotation_max`` rad)
    the sample is turned about the origin by a random rotation R: points, normals, the scene and the goal transform
    (``R T R^-1``), and the grasp vector through :func:`tohgs.geometry.grasp.transform_grasp` (its
    translation corrected through the wrist offset). :meth:`item` ``(i, draw)`` draws R from ``(seed, draw,
    i)``: training passes its step as ``draw``, so every step sees new rotations and a run is still
    reproducible; ``dataset[i]`` is draw 0. :meth:`tohgs.data.batch.Batch.collate` stacks items.
    """

    def __init__(self, paths: list[str | Path], per: str = "grasp", rotation: str = "none", seed: int = 0,
                 rotation_max: float = np.pi / 6):
        if per not in ("grasp", "config"):
            raise ValueError(f"per must be 'grasp' or 'config', not {per!r}")
        self.shards = [read_map_shard(p) for p in paths]
        self.per, self.rotation, self.seed, self.rotation_max = per, rotation, int(seed), float(rotation_max)
        self.index = [(s, r) for s, sh in enumerate(self.shards)
                      for r in range(sh.n_grasps if per == "grasp" else sh.n_configs)]
        random_rotation(np.random.default_rng(0), rotation)  # validates the mode

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return self.item(i, 0)

    def item(self, i: int, draw: int) -> dict[str, Any]:
        """Item ``i`` with the augmentation rotation of draw ``draw`` (see the class docstring)."""
        s, row = self.index[i]
        sh = self.shards[s]
        c = int(sh.grasp_config[row]) if self.per == "grasp" else row
        item: dict[str, Any] = {
            "points": sh.points[c].astype(np.float32), "normals": sh.normals[c].astype(np.float32),
            "d_init": sh.d_init[c], "d_goal": sh.d_goal[c], "scene": sh.scene[c],
            "scene_normals": sh.scene_normals[c],
            "goal_transform": network_goal_transform(sh.goal_transform[c], sh.centroid[c]).astype(np.float32),
            "object_id": int(sh.object_id[c]), "config_index": int(sh.config_index[c]), "shard": s, "row": row}
        if self.per == "grasp":
            item["grasp"] = sh.grasp[row].astype(np.float32)
            item["contact"] = sh.contact[row]
        if self.rotation != "none":
            R = random_rotation(np.random.default_rng([self.seed, int(draw), i]), self.rotation, self.rotation_max)
            item["points"] = (item["points"] @ R.T).astype(np.float32)
            item["normals"] = (item["normals"] @ R.T).astype(np.float32)
            item["scene"] = (item["scene"] @ R.T).astype(np.float32)
            item["scene_normals"] = (item["scene_normals"] @ R.T).astype(np.float32)
            T = np.eye(4)
            T[:3, :3] = R
            item["goal_transform"] = (T @ item["goal_transform"] @ T.T).astype(np.float32)
            if "grasp" in item:
                from tohgs.geometry.grasp import transform_grasp

                item["grasp"] = transform_grasp(item["grasp"][None], T, np.asarray(sh.attrs["hand_wrist"]))[0].astype(np.float32)
        return item
