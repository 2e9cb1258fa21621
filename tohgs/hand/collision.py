"""The hand's SD collision mesh: the closed hand decimated once, posed exactly with the full hand.

SD (:mod:`tohgs.metrics.quality`) simulates the hand as a static concave triangle mesh, and PyBullet's
contact detection and solver cost grows with its triangles: anny's closed hand has 1,609 vertices and 3,214
triangles, the official evaluation simulates MANO's 1,538. ``evaluation.sd_hand`` picks the mesh SD
simulates: ``full`` (the hand's closed faces) or a triangle count, for which :func:`build_collision_hand`
makes a :class:`CollisionHand`:

1. quadric decimation (open3d's ``simplify_quadric_decimation``) of the rest (flat, zero-beta) hand with its
   closed faces, to the count (the hand stays closed: watertight at 200, 800, 1,538 and 1,600 triangles);
2. each kept vertex projected onto the nearest point of the FULL rest mesh and stored as that triangle's
   three vertex ids and barycentric weights (each in [0, 1], summing to 1).

A posed collision hand is then a weighted sum of the full posed vertices (:meth:`CollisionHand.pose`): its
vertices lie on the full posed surface (each on the posed triangle it was projected onto), whatever the
grasp, and it costs nothing to pose beyond the full hand. It is built once per hand and count and cached
under ``<cache_dir>/sd_hand/<key>.npz`` (:func:`collision_hand`), keyed by the hand's rest vertices and
closed faces, the count and :data:`BUILD_VERSION`; an entry that fails :meth:`CollisionHand.validate` is
logged and rebuilt.

Measured on anny (trimesh's closest points, computed in millimetres where they are exact), the surface
deviation between the collision hand and the full closed hand, each range over the rest pose and the
``relaxed``, ``power`` and ``pinch`` presets (the rest pose gives the low end, ``power`` the high one):

- 1,600 triangles: the full vertices to the collision surface 0.05-0.09 mm median, 0.31-0.82 mm 95th
  percentile, 0.97-2.6 mm max; 50,000 area-uniform points of the collision surface to the full surface
  0.002-0.003 mm median, 0.87-2.4 mm max; its volume 0.990-0.999 of the full hand's.
- 1,538 triangles (MANO's count): 0.06-0.11 / 0.34-0.84 / 0.97-2.6 mm; 0.005-0.008 / 0.87-2.8 mm;
  0.990-0.999.
- 800 triangles: 0.25-0.46 / 0.88-1.9 / 1.6-4.1 mm; 0.11-0.18 / 1.4-4.7 mm; 0.962-0.990.

The collision hand's own vertices lie on the full surface, posed as well (0 by construction; under 1e-17 m
measured, 1e-6 m in ``tests/test_sd_hand.py``); its triangles are chords of the curved surface, so it lies
a little inside (70 % of the full vertices are outside it). The largest gaps are at the fingertips' caps at
rest and, posed, at the bent finger joints, where a collision triangle spans the crease. Per simulation
(one process on a shared 2-core machine, the variants interleaved grasp by grasp, the thread's CPU clock;
relaxed and power presets closed around the U brick and a 5 cm box at random turns, the official fixed
gravity and ``away_from_palm``; 64 simulations per variant): 1,600 triangles cost 0.61x the full hand's
129 ms (0.62x the median grasp's ratio; 0.58-0.60x in two smaller runs of 24), 800 triangles 0.36x. Of the
64 SD < 2 cm verdicts, 4 flipped at 1,600 triangles and 8 at 800, both ways alike (50 passes before and
after).
``benchmarks/bench_sd_hand.py`` compares the two on a finished run's grasps.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tohgs.hand.assets import HandAssets
from tohgs.io import content_key

log = logging.getLogger(__name__)

#: The fewest triangles ``evaluation.sd_hand`` may ask for (the schema's ``minimum``, tested equal).
MIN_TRIANGLES = 200
#: The value of ``evaluation.sd_hand`` that simulates the hand's own closed mesh.
FULL = "full"
#: Part of the cache key: raised when the build changes, so that an entry of an older build is not read.
BUILD_VERSION = 1
#: How far from 1 a cached map's weights may sum, and below 0 a weight may lie (float64 rounding).
WEIGHT_TOLERANCE = 1e-9
MM = 1000.0  # millimetres per metre


@dataclass(frozen=True)
class CollisionHand:
    """A decimated hand whose vertices are fixed barycentric points of the full hand's closed mesh.

    Attributes:
        faces: (F', 3) int64 triangles over the V' collision vertices.
        vertex_ids: (V', 3) int64 ids of the full hand's vertices (one of its closed triangles) that each
            collision vertex is a weighted sum of.
        weights: (V', 3) float64 barycentric weights, each in [0, 1], each row summing to 1.
    """

    faces: np.ndarray
    vertex_ids: np.ndarray
    weights: np.ndarray

    def validate(self, n_full_vertices: int, source: str = "collision hand") -> None:
        """Check shapes, index ranges and weights; raises ``ValueError`` naming ``source`` and the problem.

        Args:
            n_full_vertices: V, the full hand's vertex count (the range of ``vertex_ids``).
            source: what to name in an error (a cache file's path).
        """
        f, ids, w = self.faces, self.vertex_ids, self.weights
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"{source}: 'faces' must be (F, 3) integers, got {f.dtype} {f.shape}")
        if ids.ndim != 2 or ids.shape[1] != 3 or len(ids) < 3 or not np.issubdtype(ids.dtype, np.integer):
            raise ValueError(f"{source}: 'vertex_ids' must be (V, 3) integers, got {ids.dtype} {ids.shape}")
        if w.shape != ids.shape or not np.issubdtype(w.dtype, np.floating):
            raise ValueError(f"{source}: 'weights' must be floats of the shape of 'vertex_ids' {ids.shape}, "
                             f"got {w.dtype} {w.shape}")
        if f.min() < 0 or f.max() >= len(ids) or len(np.unique(f)) != len(ids):
            raise ValueError(f"{source}: 'faces' must use every one of the {len(ids)} vertices and no other")
        if ids.min() < 0 or ids.max() >= n_full_vertices:
            raise ValueError(f"{source}: 'vertex_ids' must lie in [0, {n_full_vertices}) (the hand's vertices)")
        if not np.isfinite(w).all():
            raise ValueError(f"{source}: non-finite barycentric weights")
        if w.min() < -WEIGHT_TOLERANCE or np.abs(w.sum(1) - 1.0).max() > WEIGHT_TOLERANCE:
            raise ValueError(f"{source}: barycentric weights must be non-negative and sum to 1 per vertex")

    @property
    def n_triangles(self) -> int:
        """F', the collision mesh's triangle count."""
        return len(self.faces)

    def pose(self, full_vertices: np.ndarray) -> np.ndarray:
        """The collision hand's vertices from the full hand's.

        Args:
            full_vertices: (..., V, 3) posed full-hand vertices, m (e.g. :meth:`HandAssets.vertices`).

        Returns:
            (..., V', 3) collision-hand vertices, m, float64: each the weighted sum of its three full vertices.
        """
        v = np.asarray(full_vertices, dtype=np.float64)
        return np.einsum("...vkc,vk->...vc", v[..., self.vertex_ids, :], self.weights)

    def save(self, path: str | Path) -> None:
        """Write the arrays to ``path`` as ``.npz`` (plain arrays; the caller makes it atomic)."""
        with open(path, "wb") as fh:
            np.savez(fh, faces=self.faces.astype(np.int64), vertex_ids=self.vertex_ids.astype(np.int64),
                     weights=self.weights.astype(np.float64))

    @staticmethod
    def load(path: str | Path, n_full_vertices: int) -> "CollisionHand":
        """Read what :meth:`save` wrote (``allow_pickle=False``) and :meth:`validate` it against a hand of
        ``n_full_vertices``; raises ``ValueError`` naming the file if it is not a valid one."""
        try:
            with np.load(path, allow_pickle=False) as z:
                hand = CollisionHand(np.asarray(z["faces"]), np.asarray(z["vertex_ids"]), np.asarray(z["weights"]))
        except Exception as exc:
            raise ValueError(f"{path}: not a readable collision-hand file ({exc})") from exc
        hand.validate(n_full_vertices, str(path))
        return hand


def build_collision_hand(rest_vertices: np.ndarray, closed_faces: np.ndarray, triangles: int) -> CollisionHand:
    """Decimate the closed rest hand to ``triangles`` and map its vertices onto the full mesh.

    Args:
        rest_vertices: (V, 3) the full hand's rest (flat) vertices, m.
        closed_faces: (F, 3) its closed (watertight) faces.
        triangles: the collision mesh's triangle count (quadric decimation reaches it exactly on anny's hand),
            at least :data:`MIN_TRIANGLES` and fewer than F.

    Returns:
        The :class:`CollisionHand`, validated.
    """
    import open3d as o3d
    import trimesh

    rest = np.asarray(rest_vertices, dtype=np.float64)
    faces = np.asarray(closed_faces, dtype=np.int64)
    if not MIN_TRIANGLES <= int(triangles) < len(faces):
        raise ValueError(f"a collision hand needs {MIN_TRIANGLES} <= triangles < {len(faces)} (the hand's closed "
                         f"faces), got {triangles}")
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(rest), o3d.utility.Vector3iVector(faces.astype(np.int32)))
    small = mesh.simplify_quadric_decimation(int(triangles))
    small.remove_degenerate_triangles()
    small.remove_unreferenced_vertices()
    points = np.asarray(small.vertices, dtype=np.float64)
    small_faces = np.asarray(small.triangles, dtype=np.int64)
    if len(small_faces) == 0:
        raise ValueError(f"quadric decimation of the hand to {triangles} triangles left no triangle")
    # in millimetres: at metre scale trimesh's closest point on a hand's millimetre triangles is off by up to
    # 0.02 mm (its tolerances are absolute); the weights do not depend on the unit
    full = trimesh.Trimesh(rest * MM, faces, process=False)
    closest, _, triangle = trimesh.proximity.closest_point(full, points * MM)
    ids = faces[triangle]
    w = trimesh.triangles.points_to_barycentric(rest[ids] * MM, closest)
    w = np.clip(w, 0.0, None)  # the closest point lies in its triangle: only rounding leaves it
    w /= w.sum(1, keepdims=True)
    hand = CollisionHand(small_faces, ids, w)
    hand.validate(len(rest), "the decimated hand")
    return hand


def collision_hand(hand: HandAssets, triangles: int, cache_dir: str | Path | None = None) -> CollisionHand:
    """The hand's :class:`CollisionHand` of ``triangles`` (:func:`build_collision_hand` of its rest vertices
    and closed faces), from ``<cache_dir>/sd_hand/<key>.npz`` when there, else built and stored there
    (atomically); an entry that does not load and validate is logged and rebuilt. None ``cache_dir``: built,
    not stored."""
    from tohgs.cache import load_or_compute

    rest = np.asarray(hand.rest_vertices, dtype=np.float64)
    faces = np.asarray(hand.closed_faces, dtype=np.int64)
    key = content_key(rest, faces, int(triangles), BUILD_VERSION)
    value, hit = load_or_compute(cache_dir, "sd_hand", key, ".npz",
                                 lambda: build_collision_hand(rest, faces, int(triangles)),
                                 lambda h, path: h.save(path), lambda path: CollisionHand.load(path, len(rest)))
    log.info("SD collision hand: %d triangles, %d vertices (of the full hand's %d triangles)%s", value.n_triangles,
             len(value.vertex_ids), len(faces), " from the cache" if hit else "")
    return value


def sd_hand_of(hand: HandAssets, setting: str | int, cache_dir: str | Path | None = None) -> CollisionHand | None:
    """The collision hand ``evaluation.sd_hand`` asks for: None for ``"full"`` (SD simulates the closed faces),
    else :func:`collision_hand` of that triangle count; a count at or above the hand's closed triangles is the
    full hand too (nothing to decimate). Raises ``ValueError`` naming the setting for any other value."""
    if isinstance(setting, str) and setting == FULL:
        return None
    integral = isinstance(setting, (int, np.integer)) or (isinstance(setting, float) and setting.is_integer())
    if isinstance(setting, bool) or not integral or setting < MIN_TRIANGLES:  # 1600.0 passes the schema too
        raise ValueError(f"evaluation.sd_hand must be {FULL!r} or an integer triangle count >= {MIN_TRIANGLES}, "
                         f"not {setting!r}")
    setting = int(setting)
    if setting >= len(hand.closed_faces):
        log.info("evaluation.sd_hand %d >= the hand's %d closed triangles: SD simulates the full hand", setting,
                 len(hand.closed_faces))
        return None
    return collision_hand(hand, int(setting), cache_dir)
