"""Task scenes: Placing, Stacking and Shelving configurations settled in PyBullet (paper section 3.2).

For one task and one target object, :func:`generate_scenes` tries random configurations until ``n``
are valid (or ``max_tries`` attempts are spent), counting rejections by reason:

- Placing: the target is dropped from ``drop_height`` above a random location on the table (random
  orientation) and settles (at most ``settle_time``); then the same with a random yaw at a goal location
  at least ``min_goal_distance`` away. Obstacles from the object library are dropped near the initial and
  the goal location (the target held static at both) and settle. Valid if the target stayed on the
  table and no obstacle touches it (closer than ``contact_margin``) at either pose, and every obstacle
  rests on the table.
- Stacking: a base brick and the target brick rest upright on the table (random yaw); the goal puts the
  target on top of the base (a small random offset and yaw) and simulates ``settle_time``. Valid if
  both stay stable: displacement below ``max_displacement`` and rotation below ``max_rotation``.
- Shelving: a shelf; the target is dropped from ``drop_height`` above a random location on a board at
  least ``min_board_height`` high and settles; the goal is another location on the same board; obstacles
  on that board. Valid as for Placing.

Settling stops early once every body is at rest (PhysicsSettings.rest_speed); at rest, more simulation
changes nothing, so this is the paper's "simulate 5 s" at a fraction of the cost.
"""

from __future__ import annotations

import collections
import logging
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from tohgs.assets.mesh import object_mesh
from tohgs.assets.supports import Support, Surface
from tohgs.data.scenes import SceneSet
from tohgs.sim.world import PhysicsSettings, World, quat_angle, quat_multiply, random_quaternion, yaw_quaternion

log = logging.getLogger(__name__)

TASKS = ("placing", "stacking", "shelving")
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


class Rejected(Exception):
    """A configuration attempt failed; the message is the reason counted in the log and the store."""


@dataclass(frozen=True)
class ObjectAsset:
    """An object of the library as the scenes need it: URDF, mesh vertices (m) and bounding radius."""

    name: str
    urdf: Path
    vertices: np.ndarray

    @property
    def radius(self) -> float:
        """Radius of the bounding sphere about the mesh origin (its centre of mass), m."""
        return float(np.linalg.norm(self.vertices, axis=1).max())

    def lowest(self, quat: np.ndarray) -> float:
        """The lowest z of the mesh turned by ``quat`` (xyzw), relative to its origin."""
        return float(Rotation.from_quat(quat).apply(self.vertices)[:, 2].min())

    def highest(self, quat: np.ndarray) -> float:
        """The highest z of the mesh turned by ``quat`` (xyzw), relative to its origin."""
        return float(Rotation.from_quat(quat).apply(self.vertices)[:, 2].max())


def load_object_asset(objects_dir: str | Path, name: str) -> ObjectAsset:
    """Read object ``name`` of the objects stage (``<objects_dir>/<name>/mesh.obj`` and ``object.urdf``)."""
    d = Path(objects_dir) / name
    mesh = object_mesh(objects_dir, name)
    return ObjectAsset(name, d / "object.urdf", np.asarray(mesh.vertices, dtype=np.float64))


@dataclass
class _Config:
    init: np.ndarray
    goal: np.ndarray
    support: str
    support_pose: np.ndarray
    base: str | None = None
    base_pose: np.ndarray | None = None
    obstacles: list[tuple[str, np.ndarray]] | None = None


class _Generator:
    def __init__(self, task: str, target: ObjectAsset, pool: list[ObjectAsset], supports: dict[str, Support],
                 settings: dict[str, Any], physics: PhysicsSettings, rng: np.random.Generator):
        self.task, self.target, self.pool, self.supports = task, target, pool, supports
        self.s, self.physics, self.rng = settings, physics, rng
        self.world = World(physics)

    # -- shared steps ---------------------------------------------------------------------------------
    def _drop(self, asset: ObjectAsset, xy: np.ndarray, surface_z: float, quat: np.ndarray, height: float) -> np.ndarray:
        return np.r_[xy, surface_z + height - asset.lowest(quat), quat]

    def _sample_xy(self, surface: Surface, margin: float) -> np.ndarray:
        (x0, x1), (y0, y1) = surface.x_range, surface.y_range
        if x1 - x0 <= 2 * margin or y1 - y0 <= 2 * margin:
            raise Rejected("object too large for the support surface")
        return np.array([self.rng.uniform(x0 + margin, x1 - margin), self.rng.uniform(y0 + margin, y1 - margin)])

    def _on_surface(self, pose: np.ndarray, asset: ObjectAsset, surface: Surface, tol: float = 0.01) -> bool:
        (x0, x1), (y0, y1) = surface.x_range, surface.y_range
        bottom = pose[2] + asset.lowest(pose[3:])
        return x0 <= pose[0] <= x1 and y0 <= pose[1] <= y1 and abs(bottom - surface.z) < tol

    def _settle_target(self, support: Support, xy: np.ndarray, surface: Surface, quat: np.ndarray, height: float) -> np.ndarray:
        self.world.reset()
        self.world.add_support(support)
        body = self.world.add_object(self.target.urdf, self._drop(self.target, xy, surface.z, quat, height))
        if not self.world.settle_and_verify([body]):
            raise Rejected("target did not come to rest")
        pose = self.world.pose(body)
        if not self._on_surface(pose, self.target, surface):
            raise Rejected("target did not come to rest on the support")
        return pose

    def _goal_xy(self, surface: Surface, margin: float, init_xy: np.ndarray) -> np.ndarray:
        for _ in range(50):
            xy = self._sample_xy(surface, margin)
            if np.linalg.norm(xy - init_xy) >= self.s["min_goal_distance"]:
                return xy
        raise Rejected("no goal location far enough on the support")

    def _obstacles(self, support: Support, surface: Surface, init: np.ndarray, goal: np.ndarray
                   ) -> list[tuple[str, np.ndarray]]:
        lo, hi = self.s["obstacles"]
        k = int(self.rng.integers(lo, hi + 1))
        candidates = [a for a in self.pool if a.name != self.target.name]
        if k == 0 or not candidates:
            return []
        chosen = [candidates[i] for i in self.rng.choice(len(candidates), size=min(k, len(candidates)), replace=False)]
        self.world.reset()
        self.world.add_support(support)
        held = [self.world.add_object(self.target.urdf, p, static=True) for p in (init, goal)]
        placed: list[tuple[ObjectAsset, np.ndarray, int]] = []
        gap_lo, gap_hi = self.s["obstacle_gap"]
        for asset in chosen:
            anchor = (init, goal)[int(self.rng.integers(2))]
            for _ in range(20):
                ang = self.rng.uniform(0, 2 * np.pi)
                dist = self.target.radius + asset.radius + self.rng.uniform(gap_lo, gap_hi)
                xy = anchor[:2] + dist * np.array([np.cos(ang), np.sin(ang)])
                (x0, x1), (y0, y1) = surface.x_range, surface.y_range
                inside = x0 + asset.radius <= xy[0] <= x1 - asset.radius and y0 + asset.radius <= xy[1] <= y1 - asset.radius
                clear = all(np.linalg.norm(xy - p[:2]) > asset.radius + a.radius for a, p, _ in placed) and \
                    all(np.linalg.norm(xy - p[:2]) > asset.radius + self.target.radius for p in (init, goal))
                if inside and clear:
                    break
            else:
                continue  # no room for this obstacle
            pose = self._drop(asset, xy, surface.z, random_quaternion(self.rng), 0.01)
            placed.append((asset, pose, self.world.add_object(asset.urdf, pose)))
        if not placed:
            return []
        if not self.world.settle_and_verify([b for _, _, b in placed]):
            raise Rejected("an obstacle did not come to rest")
        out = []
        for asset, _, body in placed:
            pose = self.world.pose(body)
            if not self._on_surface(pose, asset, surface, tol=0.02):
                raise Rejected("an obstacle did not come to rest on the support")
            if any(self.world.touching(body, h, self.s["contact_margin"]) for h in held):
                raise Rejected("an obstacle touches the target")
            out.append((asset.name, pose))
        return out

    # -- tasks ---------------------------------------------------------------------------------------
    def placing(self) -> _Config:
        table = self.supports["table"]
        surface = table.surfaces[0]
        margin = self.target.radius + self.s["edge_margin"]
        init = self._settle_target(table, self._sample_xy(surface, margin), surface, random_quaternion(self.rng),
                                   self.s["drop_height"])
        q_goal = quat_multiply(yaw_quaternion(self.rng.uniform(-np.pi, np.pi)), init[3:])
        goal = self._settle_target(table, self._goal_xy(surface, margin, init[:2]), surface, q_goal, self.s["drop_height"])
        obstacles = self._obstacles(table, surface, init, goal)
        return _Config(init, goal, "table", np.r_[0.0, 0.0, 0.0, IDENTITY], obstacles=obstacles)

    def shelving(self) -> _Config:
        shelves = sorted(n for n in self.supports if n.startswith("shelf-"))
        name = shelves[int(self.rng.integers(len(shelves)))]
        shelf = self.supports[name]
        boards = [s for s in shelf.surfaces if s.z >= self.s["min_board_height"]]
        if not boards:
            raise Rejected(f"{name} has no board above min_board_height")
        surface = boards[int(self.rng.integers(len(boards)))]
        q = random_quaternion(self.rng)
        height = self.target.highest(q) - self.target.lowest(q)
        if surface.clearance is not None and height + self.s["drop_height"] > surface.clearance - 0.01:
            raise Rejected("target does not fit under the next board")
        margin = self.target.radius + self.s["edge_margin"]
        init = self._settle_target(shelf, self._sample_xy(surface, margin), surface, q, self.s["drop_height"])
        q_goal = quat_multiply(yaw_quaternion(self.rng.uniform(-np.pi, np.pi)), init[3:])
        goal = self._settle_target(shelf, self._goal_xy(surface, margin, init[:2]), surface, q_goal, self.s["drop_height"])
        obstacles = self._obstacles(shelf, surface, init, goal)
        return _Config(init, goal, name, np.r_[0.0, 0.0, 0.0, IDENTITY], obstacles=obstacles)

    def stacking(self) -> _Config:
        table = self.supports["table"]
        surface = table.surfaces[0]
        bases = [a for a in self.pool if a.name != self.target.name]
        if not bases:
            raise Rejected("no other brick to stack on")
        base = bases[int(self.rng.integers(len(bases)))]
        w = self.world
        w.reset()
        w.add_support(table)
        q_base = yaw_quaternion(self.rng.uniform(-np.pi, np.pi))
        base_xy = self._sample_xy(surface, base.radius + self.s["edge_margin"])
        b_body = w.add_object(base.urdf, self._drop(base, base_xy, 0.0, q_base, 0.002))
        for _ in range(50):  # the target starts near the base, clear of it
            ang = self.rng.uniform(0, 2 * np.pi)
            dist = base.radius + self.target.radius + self.rng.uniform(self.s["min_goal_distance"], self.s["max_goal_distance"])
            xy = base_xy + dist * np.array([np.cos(ang), np.sin(ang)])
            m = self.target.radius + self.s["edge_margin"]
            if surface.x_range[0] + m <= xy[0] <= surface.x_range[1] - m and surface.y_range[0] + m <= xy[1] <= surface.y_range[1] - m:
                break
        else:
            raise Rejected("no initial location clear of the base")
        q_t = yaw_quaternion(self.rng.uniform(-np.pi, np.pi))
        t_body = w.add_object(self.target.urdf, self._drop(self.target, xy, 0.0, q_t, 0.002))
        if not w.settle_and_verify([b_body, t_body]):
            raise Rejected("a brick did not come to rest on the table")
        base_pose, init = w.pose(b_body), w.pose(t_body)
        if not (self._on_surface(base_pose, base, surface) and self._on_surface(init, self.target, surface)):
            raise Rejected("a brick did not come to rest upright on the table")
        # Goal: on top of the base, then simulate and check that both stay.
        off = self.rng.uniform(-1, 1, size=2) * self.s["max_offset"]
        q_goal = quat_multiply(yaw_quaternion(self.rng.uniform(-np.pi, np.pi)), init[3:])
        top = base_pose[2] + base.highest(base_pose[3:])
        placed = np.r_[base_pose[:2] + off, top + self.s["place_gap"] - self.target.lowest(q_goal), q_goal]
        w.set_pose(t_body, placed)
        at_rest = w.settle_and_verify([b_body, t_body], max_time=self.physics.settle_time)
        goal, base_after = w.pose(t_body), w.pose(b_body)
        disp = max(np.linalg.norm(goal[:3] - placed[:3]) - self.s["place_gap"], np.linalg.norm(base_after[:3] - base_pose[:3]))
        rot = max(quat_angle(goal[3:], placed[3:]), quat_angle(base_after[3:], base_pose[3:]))
        if disp > self.s["max_displacement"] or not at_rest:
            raise Rejected("stack not stable (displacement)")
        if rot > self.s["max_rotation"]:
            raise Rejected("stack not stable (rotation)")
        return _Config(init, goal, "table", np.r_[0.0, 0.0, 0.0, IDENTITY], base=base.name, base_pose=base_pose,
                       obstacles=[])

    def attempt(self) -> _Config:
        return getattr(self, self.task)()


def scene_seed(seed: int, task: str, name: str) -> list[int]:
    """The generator seed of one task and object: depends on the global seed, the task and the name only."""
    return [int(seed), TASKS.index(task), zlib.crc32(name.encode())]


def generate_scenes(task: str, target: ObjectAsset, pool: list[ObjectAsset], supports: dict[str, Support],
                    settings: dict[str, Any], physics: PhysicsSettings, n: int, max_tries: int, allow_fewer: bool,
                    seed: int) -> SceneSet:
    """Generate ``n`` valid configurations of ``task`` for ``target``.

    Args:
        task: ``placing``, ``stacking`` or ``shelving``.
        target: the object to be grasped.
        pool: obstacles (Placing, Shelving) or base bricks (Stacking) to draw from; the target is skipped.
        supports: the table and shelves by name.
        settings: the task's block of the ``scenes`` config.
        physics: simulation settings.
        n: valid configurations wanted.
        max_tries: attempts before giving up.
        allow_fewer: with too few valid configurations after ``max_tries``, write what there is instead of
            failing.
        seed: the generator's seed (all draws derive from it).

    Raises:
        RuntimeError: fewer than ``n`` valid configurations and not ``allow_fewer``; the message names the
            task, the object and the counts by reason.
    """
    if task not in TASKS:
        raise ValueError(f"unknown task '{task}' (expected one of {TASKS})")
    rng = np.random.default_rng(scene_seed(seed, task, target.name))
    gen = _Generator(task, target, pool, supports, settings, physics, rng)
    configs: list[_Config] = []
    rejections: collections.Counter[str] = collections.Counter()
    tries = 0
    try:
        from tqdm import tqdm

        bar = tqdm(total=n, desc=f"{task}/{target.name}", mininterval=2.0)
        while len(configs) < n and tries < max_tries:
            tries += 1
            try:
                configs.append(gen.attempt())
                bar.update(1)
            except Rejected as exc:
                rejections[str(exc)] += 1
        bar.close()
    finally:
        gen.world.close()
    summary = ", ".join(f"{r}: {c}" for r, c in rejections.most_common()) or "none"
    log.info("%s/%s: %d valid of %d tries; rejections: %s", task, target.name, len(configs), tries, summary)
    if len(configs) < n and not allow_fewer:
        raise RuntimeError(f"{task} scenes for object '{target.name}' (seed {seed}): only {len(configs)} valid "
                           f"configurations of {n} wanted after {tries} tries; rejections: {summary}")
    return _to_scene_set(task, target.name, configs, supports, seed, n, tries, rejections)


def _to_scene_set(task: str, target: str, configs: list[_Config], supports: dict[str, Support], seed: int, n: int,
                  tries: int, rejections: dict[str, int]) -> SceneSet:
    names = sorted({o for c in configs for o, _ in (c.obstacles or [])} | {c.base for c in configs if c.base})
    index = {nm: i for i, nm in enumerate(names)}
    support_names = sorted(supports)
    offsets = np.cumsum([0] + [len(c.obstacles or []) for c in configs]).astype(np.int64)
    obs = [(index[o], p) for c in configs for o, p in (c.obstacles or [])]
    nan7 = np.full(7, np.nan)
    return SceneSet(
        task=task, object=target,
        target_init_pose=np.array([c.init for c in configs], dtype=np.float64).reshape(-1, 7),
        target_goal_pose=np.array([c.goal for c in configs], dtype=np.float64).reshape(-1, 7),
        support_id=np.array([support_names.index(c.support) for c in configs], dtype=np.int32),
        support_pose=np.array([c.support_pose for c in configs], dtype=np.float64).reshape(-1, 7),
        base_id=np.array([index[c.base] if c.base else -1 for c in configs], dtype=np.int32),
        base_pose=np.array([c.base_pose if c.base else nan7 for c in configs], dtype=np.float64).reshape(-1, 7),
        obstacle_offsets=offsets,
        obstacle_id=np.array([i for i, _ in obs], dtype=np.int32),
        obstacle_pose=np.array([p for _, p in obs], dtype=np.float64).reshape(-1, 7),
        objects=names, supports=support_names,
        attrs={"seed": int(seed), "n_requested": int(n), "tries": int(tries), "rejections": dict(rejections)},
    )


def load_configuration(world: World, scenes: SceneSet, c: int, objects_dir: str | Path, supports: dict[str, Support],
                       which: str = "init", static: bool = False,
                       colors: dict[str, tuple[float, float, float, float]] | None = None) -> dict[str, Any]:
    """Build configuration ``c`` of ``scenes`` in ``world`` (after a reset), the target at its ``which`` pose.

    Returns the body ids: ``{"target": id, "base": id or None, "obstacles": [ids], "support": [ids]}``.
    """
    if which not in ("init", "goal"):
        raise ValueError(f"which must be 'init' or 'goal', got {which!r}")
    colors = colors or {}
    world.reset()
    name, pose = scenes.support(c)
    out: dict[str, Any] = {"support": world.add_support(supports[name], pose), "base": None, "obstacles": []}
    base = scenes.base(c)
    if base is not None:
        out["base"] = world.add_object(Path(objects_dir) / base[0] / "object.urdf", base[1], static=static,
                                       color=colors.get("base"))
    for oname, opose in scenes.obstacles(c):
        out["obstacles"].append(world.add_object(Path(objects_dir) / oname / "object.urdf", opose, static=static,
                                                 color=colors.get("obstacle")))
    target_pose = scenes.target_init_pose[c] if which == "init" else scenes.target_goal_pose[c]
    out["target"] = world.add_object(Path(objects_dir) / scenes.object / "object.urdf", target_pose, static=static,
                                     color=colors.get("target"))
    return out


def _generate_job(task: str, target: str, pool: list[str], objects_dir: str, supports_json: str,
                  settings: dict[str, Any], seed: int) -> SceneSet:
    from tohgs.assets.supports import read_supports

    supports = read_supports(supports_json)
    assets = {n: load_object_asset(objects_dir, n) for n in sorted(set(pool) | {target})}
    physics = PhysicsSettings(**settings["physics"])
    task_settings = {**settings[task], "contact_margin": settings["contact_margin"]}
    scenes = generate_scenes(task, assets[target], [assets[n] for n in pool], supports, task_settings, physics,
                             settings["n_configs"], settings["max_tries"], settings["allow_fewer"], seed)
    return scenes


def make_scene_store(task: str, target: str, pool: list[str], objects_dir: str | Path, supports_json: str | Path,
                     settings: dict[str, Any], seed: int, out: str | Path) -> SceneSet:
    """The scenes stage for one task and object: generate (in a crash-isolated process) and write the store.

    Args:
        task, target: the task and the target object's name.
        pool: the accepted objects of the task's set (obstacles for Placing and Shelving, base bricks for
            Stacking); the target itself is never drawn.
        objects_dir: the objects stage's folder (``results/objects``).
        supports_json: the supports file of the objects stage.
        settings: the ``scenes`` config block (the part this task uses is recorded in the store).
        seed: the global seed.
        out: the store's path.
    """
    from tohgs.data.scenes import write_scenes
    from tohgs.sim.isolation import run_isolated

    if target not in pool:
        raise ValueError(f"'{target}' is not in the {task} pool of accepted objects")
    what = f"{task} scenes for object '{target}', seed {seed}"
    log.info("generating %s", what)
    scenes = run_isolated(_generate_job, dict(task=task, target=target, pool=list(pool), objects_dir=str(objects_dir),
                                              supports_json=str(supports_json), settings=settings, seed=seed), what)
    scenes.attrs["config"] = {k: settings[k] for k in ("n_configs", "max_tries", "allow_fewer", "physics",
                                                       "contact_margin", task)}
    write_scenes(scenes, out)
    return scenes
