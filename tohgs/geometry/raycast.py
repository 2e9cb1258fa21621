"""Exact queries against triangle meshes through open3d's ray-casting scene (torch-free).

Signed distance (negative inside a watertight mesh, metres) and occupancy, for any number of points at
once. :mod:`tohgs.geometry.sdf` samples the signed distance on a grid for the
optimiser; the metrics and the task expansion query meshes directly.
"""

from __future__ import annotations

import numpy as np
import trimesh


def raycasting_scene(vertices: np.ndarray, faces: np.ndarray):
    """An open3d ray-casting scene of one triangle mesh ((V, 3) metres, (F, 3)): distances, occupancy."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)))
    return scene


def exact_signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Exact signed distance of (N, 3) points to a watertight mesh (negative inside), metres."""
    import open3d as o3d

    pts = o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32))
    return raycasting_scene(mesh.vertices, mesh.faces).compute_signed_distance(pts).numpy().astype(np.float64)


def occupancy(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: which of (N, 3) points lie inside the closed mesh ((V, 3) metres, (F, 3))."""
    import open3d as o3d

    pts = o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32))
    return raycasting_scene(vertices, faces).compute_occupancy(pts).numpy() > 0.5
