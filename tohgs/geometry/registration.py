"""Rigid registration of an object's cloud into another scene by multi-start ICP, and the error of an
estimated transform against the true one. F-GraspTTA estimates the target's init-to-goal transform with it
(:mod:`tohgs.methods.filtered`).

ICP converges to the nearest local optimum, and an object resettled at its goal pose may be turned by any
angle, so the search starts from many rotations: the 24 rotations of the cube, each composed with turns of
``90 / z_turns`` degrees about the vertical (72 starts with the default 3), every start with the two clouds'
centroids aligned. The result with the smallest symmetric Chamfer distance between the carried source and
the target wins (ICP's own fitness saturates: every turn of a compact object puts most points within the
correspondence distance). A symmetric object (a brick) has several equally good answers; ICP
cannot tell them apart, and neither can anyone looking at the cloud.

ICP is point-to-point with open3d's iteration (``registration_icp``): the correspondences are each source
point's nearest target point within ``max_distance``; fitness is their share of the source points and the
inlier RMSE their root mean squared distance; each iteration moves the source by the rigid transform
that best aligns the correspondences (Umeyama, no scaling) and stops when neither fitness nor RMSE changed
by 1e-6 or after ``max_iterations``. :func:`register_many` runs every start of several registrations as one
vectorised loop (one k-d tree per target, the alignments of all starts as one batched SVD);
:func:`register_open3d` is the slow reference, one open3d call per start, which it matches to rounding.
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


RELATIVE_CHANGE = 1e-6  # ICP stops when fitness and inlier RMSE both changed by less (open3d's default criteria)


def register(source: np.ndarray, target: np.ndarray, settings: ICPSettings = ICPSettings()) -> Registration:
    """The rigid transform carrying the (N, 3) ``source`` cloud onto the (M, 3) ``target`` cloud (m), by
    point-to-point ICP from every start rotation (module docstring). Deterministic."""
    return register_many([(source, target)], settings)[0]


def _umeyama(src: np.ndarray, tgt: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(K, 4, 4) the rigid transforms that best align the (K, N, 3) ``src`` points with ``weight`` (K, N)
    1 (a correspondence) or 0 onto (K, N, 3) ``tgt`` (least squares, no scaling; the identity where a
    problem has no correspondence)."""
    n = weight.sum(1)
    has = n > 0
    inv = np.where(has, 1.0 / np.maximum(n, 1.0), 0.0)[:, None]
    w = weight[..., None]
    mean_s = (w * src).sum(1) * inv  # (K, 3)
    mean_t = (w * tgt).sum(1) * inv
    sigma = np.matmul((w * (tgt - mean_t[:, None])).transpose(0, 2, 1), src - mean_s[:, None]) * inv[..., None]
    u, _, vt = np.linalg.svd(sigma)
    flip = np.linalg.det(u) * np.linalg.det(vt) < 0
    u[flip, :, 2] *= -1.0
    rot = u @ vt
    out = np.tile(np.eye(4), (len(src), 1, 1))
    out[has, :3, :3] = rot[has]
    out[has, :3, 3] = mean_t[has] - np.matmul(rot[has], mean_s[has, :, None])[..., 0]
    return out


def _correspondences(tree, moved: np.ndarray, max_distance: float, target: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For (K, N, 3) moved source points: each one's nearest target point (K, N, 3), whether it is within
    ``max_distance`` (K, N) float, and the squared distance (K, N) (0 where none)."""
    d, idx = tree.query(moved.reshape(-1, 3), k=1, distance_upper_bound=max_distance)
    found = np.isfinite(d).reshape(moved.shape[:2])
    idx = np.where(found.reshape(-1), idx, 0)
    return target[idx].reshape(moved.shape), found.astype(np.float64), np.where(found, d.reshape(found.shape), 0.0) ** 2


def _scores(found: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) fitness (the share of source points with a correspondence) and inlier RMSE (0 without any)."""
    n = found.sum(1)
    return n / found.shape[1], np.sqrt(np.where(n > 0, d2.sum(1) / np.maximum(n, 1.0), 0.0))


def register_many(pairs: list[tuple[np.ndarray, np.ndarray]], settings: ICPSettings = ICPSettings()
                  ) -> list[Registration]:
    """:func:`register` of several (source (N_p, 3), target (M_p, 3)) pairs: every start of every pair
    iterates in one loop, each its own ICP (its correspondences in its pair's target, its own stop), so a
    pair's result does not depend on the others. Deterministic."""
    from scipy.spatial import cKDTree

    starts = start_rotations(settings.z_turns)
    k = len(starts)
    probs = []  # per pair: the clouds, their trees, the starts' transforms and moved source points
    for source, target in pairs:
        src = np.asarray(source, dtype=np.float64)
        tgt = np.asarray(target, dtype=np.float64)
        if len(src) < 3 or len(tgt) < 3:
            raise ValueError(f"ICP needs at least 3 points per cloud, got {len(src)} and {len(tgt)}")
        init = np.tile(np.eye(4), (k, 1, 1))
        init[:, :3, :3] = starts
        init[:, :3, 3] = tgt.mean(0) - starts @ src.mean(0)
        moved = np.matmul(src, starts.transpose(0, 2, 1)) + init[:, None, :3, 3]
        tree = cKDTree(tgt)
        near, found, d2 = _correspondences(tree, moved, settings.max_distance, tgt)
        fit, rmse = _scores(found, d2)
        probs.append({"src": src, "tgt": tgt, "tree_t": tree, "tree_s": cKDTree(src), "T": init, "moved": moved,
                      "near": near, "found": found, "fit": fit, "rmse": rmse, "active": np.ones(k, bool)})
    for _ in range(settings.max_iterations):
        live = [p for p in probs if p["active"].any()]
        if not live:
            break
        # the alignment of every active start of every pair as one batch
        update = _umeyama(np.concatenate([p["moved"][p["active"]] for p in live]),
                          np.concatenate([p["near"][p["active"]] for p in live]),
                          np.concatenate([p["found"][p["active"]] for p in live]))
        at = 0
        for p in live:
            a = np.flatnonzero(p["active"])
            up = update[at:at + len(a)]
            at += len(a)
            p["T"][a] = up @ p["T"][a]
            moved = np.matmul(p["moved"][a], up[:, :3, :3].transpose(0, 2, 1)) + up[:, None, :3, 3]
            near, found, d2 = _correspondences(p["tree_t"], moved, settings.max_distance, p["tgt"])
            fit, rmse = _scores(found, d2)
            done = (np.abs(fit - p["fit"][a]) < RELATIVE_CHANGE) & (np.abs(rmse - p["rmse"][a]) < RELATIVE_CHANGE)
            p["moved"][a], p["near"][a], p["found"][a], p["fit"][a], p["rmse"][a] = moved, near, found, fit, rmse
            p["active"][a[done]] = False
    out = []
    for p in probs:
        T, src, tgt = p["T"], p["src"], p["tgt"]
        carried = np.matmul(src, T[:, :3, :3].transpose(0, 2, 1)) + T[:, None, :3, 3]
        back = np.matmul(tgt[None] - T[:, None, :3, 3], T[:, :3, :3])  # the target in the source's frame
        chamfer = 0.5 * (p["tree_t"].query(carried.reshape(-1, 3))[0].reshape(k, -1).mean(1)
                         + p["tree_s"].query(back.reshape(-1, 3))[0].reshape(k, -1).mean(1))
        best = 0
        for i in range(1, k):  # the first start of the smallest chamfer (ties within 1e-12 keep the earlier)
            if chamfer[i] < chamfer[best] - 1e-12:
                best = i
        out.append(Registration(T[best].copy(), float(p["fit"][best]), float(chamfer[best])))
    return out


def register_open3d(source: np.ndarray, target: np.ndarray, settings: ICPSettings = ICPSettings()) -> Registration:
    """The slow reference of :func:`register`: one open3d ``registration_icp`` per start rotation, the
    same starts and choice (module docstring)."""
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
