"""Point clouds and the paper's per-point maps (section 4.1; REFERENCE.md "Maps").

- Object cloud: N points on the target's surface with their normals (area-weighted, seeded).
- Scene cloud: the scene meshes (table or shelf, obstacles, base brick; never the target) sampled densely,
  merged and farthest-point sampled to N_s points.
- Distance map: for each object point the distance d to the closest scene point; contact map: the
  distance to the closest hand vertex. Both are normalised as the official code does,
  ``D = 1 - 2 (sigmoid(alpha d) - 0.5)``, in (0, 1] with 1 at contact (alpha 30 for distances, 100 for
  contact); the paper's printed ``1 - 2 sigmoid(alpha d - 0.5)`` does not map to [0, 1].

Nearest neighbours come from a k-d tree (scipy's cKDTree): O((N + M) log M) instead of the N x M
all-pairs distances of :func:`nearest_distance_brute` (kept for tests and the benchmark).

:data:`ALPHA_DISTANCE` and :data:`ALPHA_CONTACT` are the two alphas' one home in the library (the config's
``maps.alpha_distance`` and ``maps.alpha_contact`` default to the same in the schema). The networks read
them for their defaults, so this module imports only numpy at import time (scipy and trimesh where used).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from tohgs.geometry.sampling import farthest_point_sampling

if TYPE_CHECKING:
    import trimesh

#: The distance maps' alpha (1/m): the sharpness of ``1 - 2 (sigmoid(alpha d) - 0.5)`` for scene distances.
ALPHA_DISTANCE = 30.0
#: The contact maps' alpha (1/m): the same for the distance to the nearest hand vertex (sharper).
ALPHA_CONTACT = 100.0


def normalised_map(d: np.ndarray, alpha: float) -> np.ndarray:
    """``1 - 2 (sigmoid(alpha d) - 0.5)`` of distances ``d`` (m, >= 0): 1 at contact, -> 0 far away."""
    return 1.0 - 2.0 * (1.0 / (1.0 + np.exp(-alpha * np.asarray(d, dtype=np.float64))) - 0.5)


def nearest_distance(points: np.ndarray, cloud: np.ndarray) -> np.ndarray:
    """(N,) distance from each of (N, 3) ``points`` to its nearest point of (M, 3) ``cloud``, m."""
    from scipy.spatial import cKDTree

    if len(cloud) == 0:
        return np.full(len(points), np.inf)
    return cKDTree(np.asarray(cloud, dtype=np.float64)).query(np.asarray(points, dtype=np.float64), k=1)[0]


def nearest_distance_brute(points: np.ndarray, cloud: np.ndarray, chunk: int = 512) -> np.ndarray:
    """The same as :func:`nearest_distance` by all-pairs distances (chunked over ``points``)."""
    p, c = np.asarray(points, dtype=np.float64), np.asarray(cloud, dtype=np.float64)
    out = np.empty(len(p))
    for i in range(0, len(p), chunk):
        d2 = ((p[i:i + chunk, None, :] - c[None]) ** 2).sum(-1)
        out[i:i + chunk] = np.sqrt(d2.min(1))
    return out


def sample_surface(mesh: trimesh.Trimesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) points uniformly on ``mesh``'s surface (area-weighted) and their (n, 3) unit face normals."""
    areas = np.asarray(mesh.area_faces, dtype=np.float64)
    if areas.sum() <= 0:
        raise ValueError("cannot sample a mesh with zero surface area")
    face = rng.choice(len(areas), size=n, p=areas / areas.sum())
    tri = np.asarray(mesh.triangles)[face]
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    return pts, np.asarray(mesh.face_normals)[face]


def scene_cloud(meshes: list[trimesh.Trimesh], n: int, rng: np.random.Generator, oversample: int = 4,
                centres: np.ndarray | None = None, radius: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) points of the merged scene meshes and their (n, 3) outward unit face normals: area-weighted
    samples, then farthest-point sampling to ``n`` (even coverage of large and small parts alike). The
    normals let a method tell inside from outside (:mod:`tohgs.geometry.cloud`), as a depth sensor's
    estimated normals would.

    With ``radius`` > 0, only the scene within ``radius`` of any of the (K, 3) ``centres`` is kept (the
    target's initial and goal positions): the same ``n`` points then resolve the neighbourhood that the
    distance maps measure instead of the whole 1.5 m table. Samples are drawn in rounds until
    ``oversample * n`` of them fall inside (or 20 rounds pass).
    """
    import trimesh

    if not meshes:
        raise ValueError("a scene needs at least one mesh")
    merged = trimesh.util.concatenate(meshes)
    want = oversample * n
    if radius <= 0 or centres is None:
        dense, dense_n = sample_surface(merged, want, rng)
    else:
        c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
        kept: list[np.ndarray] = []
        kept_n: list[np.ndarray] = []
        total = 0
        for _ in range(20):
            pts, nrm = sample_surface(merged, want, rng)
            near = nearest_distance(pts, c) <= radius
            kept.append(pts[near])
            kept_n.append(nrm[near])
            total += int(near.sum())
            if total >= want:
                break
        dense, dense_n = np.concatenate(kept)[:want], np.concatenate(kept_n)[:want]
        if len(dense) < n:
            raise ValueError(f"only {len(dense)} scene samples within {radius} m of the target; need {n}")
    pick = farthest_point_sampling(dense, n, start=int(rng.integers(len(dense))))
    return dense[pick], dense_n[pick]
