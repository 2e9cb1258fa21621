"""Farthest-point sampling of point sets: the scene clouds of the maps (:mod:`tohgs.geometry.maps`) and the
hand's vertex subset of the prior synthesis (:mod:`tohgs.grasps.synthesis`) share it, and it lives apart from
both, so that an edit to the maps' code does not make the prior grasps stale (their derived code inputs).
"""

from __future__ import annotations

import numpy as np


def farthest_point_sampling(points: np.ndarray, k: int, start: int = 0) -> np.ndarray:
    """Indices of ``k`` of (M, 3) ``points`` by farthest-point sampling from index ``start``
    (all indices when M <= k), in increasing order.

    open3d's C++ loop (about 15x faster than the numpy loop of
    :func:`farthest_point_sampling_reference`, with which it agrees); its points are mapped back to
    indices by an exact nearest-neighbour lookup."""
    import open3d as o3d
    from scipy.spatial import cKDTree

    m = len(points)
    if m <= k:
        return np.arange(m)
    p = np.ascontiguousarray(points, dtype=np.float64)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    picked = np.asarray(cloud.farthest_point_down_sample(int(k), int(start)).points)
    _, idx = cKDTree(p).query(picked)
    return np.asarray(idx, dtype=np.int64)


def farthest_point_sampling_reference(points: np.ndarray, k: int, start: int = 0) -> np.ndarray:
    """:func:`farthest_point_sampling` as a plain numpy loop, O(k M): the reference the tests compare with."""
    m = len(points)
    if m <= k:
        return np.arange(m)
    p = np.asarray(points, dtype=np.float64)
    chosen = np.empty(k, dtype=np.int64)
    chosen[0] = start
    d = ((p - p[start]) ** 2).sum(1)
    for i in range(1, k):
        chosen[i] = int(np.argmax(d))
        d = np.minimum(d, ((p - p[chosen[i]]) ** 2).sum(1))
    return chosen
