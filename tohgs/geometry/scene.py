"""A configuration's scene as meshes, and the collision queries against it (open3d ray casting).

The scene of a configuration is every mesh but the target's: the support (table or shelf), the base brick
(Stacking) and the obstacles, placed at their world poses (:mod:`tohgs.data.scenes`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from tohgs.assets.mesh import object_mesh
from tohgs.geometry.grasp import pose_matrix


def _cached_object(objects_dir: str | Path, name: str, cache: dict[str, trimesh.Trimesh]) -> trimesh.Trimesh:
    if name not in cache:
        cache[name] = object_mesh(objects_dir, name)
    return cache[name]


def obstacle_meshes(scenes, c: int, objects_dir: str | Path, meshes: dict[str, trimesh.Trimesh] | None = None
                    ) -> list[trimesh.Trimesh]:
    """World-frame meshes of configuration ``c``'s obstacles (neither the support nor the base brick).
    ``meshes`` caches object meshes by name."""
    cache = {} if meshes is None else meshes
    return [_cached_object(objects_dir, o, cache).copy().apply_transform(pose_matrix(p)) for o, p in scenes.obstacles(c)]


def scene_meshes(scenes, c: int, objects_dir: str | Path, supports: dict, meshes: dict[str, trimesh.Trimesh] | None = None
                 ) -> list[trimesh.Trimesh]:
    """World-frame meshes of configuration ``c``'s scene without the target: the support (table or shelf),
    the base brick (Stacking) and the obstacles. ``meshes`` caches object meshes by name."""
    cache = {} if meshes is None else meshes
    sname, spose = scenes.support(c)
    skey = f"support:{sname}"
    if skey not in cache:
        cache[skey] = supports[sname].mesh()
    out = [cache[skey].copy().apply_transform(pose_matrix(spose))]
    base = scenes.base(c)
    if base is not None:
        out.append(_cached_object(objects_dir, base[0], cache).copy().apply_transform(pose_matrix(base[1])))
    return out + obstacle_meshes(scenes, c, objects_dir, cache)


def obstacle_gaps(scenes, c: int, objects_dir: str | Path, target_points: np.ndarray,
                  meshes: dict[str, trimesh.Trimesh] | None = None) -> tuple[float, float]:
    """The gap between the target and its nearest obstacle in configuration ``c``, at the initial and at
    the goal pose, m: the smallest distance from the target's (N, 3) surface points (its mesh frame) to an
    obstacle's surface (0 where they touch); NaN for a configuration without obstacles. The support and the
    base brick, which the target rests on, are not obstacles."""
    from tohgs.geometry.raycast import raycasting_scene

    obstacles = obstacle_meshes(scenes, c, objects_dir, meshes)
    if not obstacles:
        return float("nan"), float("nan")
    import open3d as o3d

    merged = trimesh.util.concatenate(obstacles)
    scene = raycasting_scene(merged.vertices, merged.faces)
    gaps = []
    for pose in (scenes.target_init_pose[c], scenes.target_goal_pose[c]):
        T = pose_matrix(pose)
        pts = np.asarray(target_points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
        d = scene.compute_distance(o3d.core.Tensor(np.ascontiguousarray(pts, dtype=np.float32))).numpy()
        gaps.append(float(d.min()))
    return gaps[0], gaps[1]


class SceneCollider:
    """Occupancy and depth queries against a set of closed world-frame meshes (open3d ray casting)."""

    def __init__(self, meshes: list[trimesh.Trimesh]):
        from tohgs.geometry.raycast import raycasting_scene

        merged = trimesh.util.concatenate(meshes)
        self.scene = raycasting_scene(merged.vertices, merged.faces)

    def depth_inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) how deep each of (N, 3) points lies inside the meshes (0 outside), m."""
        import open3d as o3d

        pts = o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32))
        inside = self.scene.compute_occupancy(pts).numpy() > 0.5
        depth = np.zeros(len(points))
        if inside.any():
            sub = o3d.core.Tensor(np.ascontiguousarray(np.asarray(points)[inside], dtype=np.float32))
            depth[inside] = self.scene.compute_distance(sub).numpy()
        return depth


def collision_free(hand_vertices: np.ndarray, collider: SceneCollider, tolerance: float) -> np.ndarray:
    """(B,) bool: hands ((B, V, 3) world frame) with no vertex deeper than ``tolerance`` in the scene."""
    b, v, _ = hand_vertices.shape
    depth = collider.depth_inside(hand_vertices.reshape(-1, 3)).reshape(b, v)
    return depth.max(1) <= tolerance
