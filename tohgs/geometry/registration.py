"""Rigid registration of an object's cloud into another scene by multi-start ICP (open3d), and the error
of an estimated transform against the true one. F-GraspTTA estimates the target's init-to-goal transform
with it (:mod:`tohgs.methods.filtered`).

ICP converges to the nearest local optimum, and an object resettled at its goal pose may be turned by any
angle, so the search starts from many rotations: the 24 rotations of the cube, each composed with turns of
``90 / z_turns`` degrees about the vertical (72 starts with the default 3), every start with the two clouds'
centroids aligned. The result with the smallest symmetric Chamfer distance between the carried source and
the target wins (ICP's own fitness saturates: every turn of a compact object puts most points within the
correspondence distance). A symmetric object (a brick) has several equally good answers; ICP
cannot tell them apart, and neither can anyone looking at the cloud.

:func:`register_many` registers the pairs of several configurations one after the other. A re-implementation
of open3d's iteration vectorised over every start of every pair (numpy, one k-d tree per target, one
batched SVD per iteration) matched open3d to 1e-14 but took 1.5x its CPU time on the default's clouds
(512 source points), so open3d stays (docs/baselines.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ICPSettings:
    """``z_turns`` vertical turns per cube rotation; ``max_iterations`` per start; ``max_distance`` the
    correspondence distance (m)."""

    z_turns: int = 3
    max_iterations: int = 40
    max_distance: float = 0.02


@dataclass(frozen=True)
class Registration:
    """``transform`` (4, 4) carrying the source onto the target; ``fitness`` the share of source points
    with a target point within ``max_distance``; ``chamfer`` the mean of the two clouds' mean nearest
    distances after the transform, m."""

    transform: np.ndarray
    fitness: float
    chamfer: float


def cube_rotations() -> np.ndarray:
    """(24, 3, 3) the proper rotations of the cube (signed permutation matrices of determinant 1)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[range(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(m)
    return np.stack(out)


def start_rotations(z_turns: int) -> np.ndarray:
    """(24 z_turns, 3, 3) the starts: each cube rotation after a turn of ``k 90 / z_turns`` degrees about z."""
    out = []
    for k in range(max(1, z_turns)):
        a = np.pi / 2 * k / max(1, z_turns)
        rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        out += [r @ rz for r in cube_rotations()]
    return np.stack(out)


def register(source: np.ndarray, target: np.ndarray, settings: ICPSettings = ICPSettings()) -> Registration:
    """The rigid transform carrying the (N, 3) ``source`` cloud onto the (M, 3) ``target`` cloud (m), by
    point-to-point ICP from every start rotation (module docstring). Deterministic."""
    import open3d as o3d
    from scipy.spatial import cKDTree

    src = np.asarray(source, dtype=np.float64)
    tgt = np.asarray(target, dtype=np.float64)
    if len(src) < 3 or len(tgt) < 3:
        raise ValueError(f"ICP needs at least 3 points per cloud, got {len(src)} and {len(tgt)}")
    pcd_s = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src))
    pcd_t = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt))
    cs, ct = src.mean(0), tgt.mean(0)
    criteria = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=settings.max_iterations)
    estimation = o3d.pipelines.registration.TransformationEstimationPointToPoint()
    tree_s, tree_t = cKDTree(src), cKDTree(tgt)
    best: Registration | None = None
    for rot in start_rotations(settings.z_turns):
        init = np.eye(4)
        init[:3, :3] = rot
        init[:3, 3] = ct - rot @ cs
        res = o3d.pipelines.registration.registration_icp(pcd_s, pcd_t, settings.max_distance, init, estimation,
                                                          criteria)
        T = np.asarray(res.transformation).copy()
        moved = src @ T[:3, :3].T + T[:3, 3]
        back = (tgt - T[:3, 3]) @ T[:3, :3]  # the target in the source's frame
        chamfer = 0.5 * (tree_t.query(moved)[0].mean() + tree_s.query(back)[0].mean())
        if best is None or chamfer < best.chamfer - 1e-12:
            best = Registration(T, float(res.fitness), float(chamfer))
    return best


def register_many(pairs: list[tuple[np.ndarray, np.ndarray]], settings: ICPSettings = ICPSettings()
                  ) -> list[Registration]:
    """:func:`register` of each (source (N_p, 3), target (M_p, 3)) pair, in order (module docstring)."""
    return [register(source, target, settings) for source, target in pairs]


def transform_error(estimate: np.ndarray, truth: np.ndarray, points: np.ndarray) -> dict[str, float]:
    """How far a (4, 4) ``estimate`` is from the ``truth``: the angle of ``R_est R_true^T`` (degrees), the
    distance of the translations (m) and the mean distance of the (N, 3) ``points`` carried by each (m)."""
    e, t = np.asarray(estimate, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    rel = e[:3, :3] @ t[:3, :3].T
    angle = np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1.0, 1.0)))
    p = np.asarray(points, dtype=np.float64)
    moved_e = p @ e[:3, :3].T + e[:3, 3]
    moved_t = p @ t[:3, :3].T + t[:3, 3]
    return {"rotation_deg": float(angle), "translation_m": float(np.linalg.norm(e[:3, 3] - t[:3, 3])),
            "point_m": float(np.linalg.norm(moved_e - moved_t, axis=1).mean())}
