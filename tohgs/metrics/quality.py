"""Grasp quality metrics of the evaluation protocol, written once and reused by every stage.

- PV, penetration volume: the object at its pose voxelised at a 1 mm pitch (surface voxels, as trimesh's
  ``voxelized`` returns them); the voxel centres inside the closed hand mesh are counted, times the voxel
  volume. m^3 (tables report cm^3).
- SD, simulation displacement: PyBullet, the hand a static concave triangle mesh (mass 0, friction 3,
  restitution 0); the object its convex decomposition, mass 1, friction 3, restitution 0.5, its inertial
  frame at the mesh's vertex mean; time step 1/240 s, 150 solver iterations, 35 steps (the official
  code's setting, not the paper's "1 s"); SD is how far the object's centre moved, m; a failed simulation
  counts 0.10 m. Gravity is a setting (``gravity_direction``): the official code applies it along +y of
  its camera-derived frame, which has no meaning for tohgs's grasps. ``"away_from_palm"`` (the default)
  pulls the object from the palm centre through the object's centre: the direction it is lifted against
  when the hand approaches from the free side of its support (a table top, a shelf board), whatever
  orientation the object rests in; ``"fixed"`` uses the ``gravity`` vector of the grasp's frame (for
  grasps in the world frame, -z).
- Robust SD (beyond the protocol): SD again under K tiny perturbations of the start (the hand moved by at
  most half a millimetre, the solver's iterations jittered), for a few grasps per configuration
  (:class:`RobustSDSettings`); the protocol's single SD stays the paper's QR.
- Contact: PV > 0, and separately the smallest signed distance from the hand's vertices to the object's
  surface (negative inside), m.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from tohgs.cache import load_or_compute
from tohgs.geometry.grasp import pose_matrix
from tohgs.geometry.raycast import exact_signed_distance, occupancy
from tohgs.io import content_key

log = logging.getLogger(__name__)

VOXEL_PITCH = 0.001  # m


def surface_voxels(mesh: trimesh.Trimesh, pitch: float = VOXEL_PITCH, cache_dir: str | Path | None = None) -> np.ndarray:
    """(N, 3) centres of the surface voxels of ``mesh`` at ``pitch`` (metres, the mesh's frame), as trimesh's
    ``voxelized`` returns them. That takes seconds per object, so with ``cache_dir`` they are kept under
    ``<cache_dir>/voxels/<key>.npy`` (keyed by the mesh's vertices and faces and the pitch): the prior-grasp
    and evaluation jobs of an object share them; an unreadable entry is recomputed and replaced."""
    key = content_key(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), float(pitch))

    def save(voxels: np.ndarray, path: Path) -> None:
        with open(path, "wb") as fh:
            np.save(fh, voxels)

    voxels, _ = load_or_compute(cache_dir, "voxels", key, ".npy",
                                lambda: np.asarray(mesh.voxelized(pitch).points, dtype=np.float64), save,
                                lambda path: np.load(path, allow_pickle=False))
    return voxels


def penetration_volume(hand_vertices: np.ndarray, hand_faces: np.ndarray, voxels: np.ndarray,
                       pitch: float = VOXEL_PITCH) -> np.ndarray:
    """PV of each hand: object surface voxels inside the closed hand mesh times the voxel volume.

    Args:
        hand_vertices: (B, V, 3) or (V, 3) hand vertices, metres, in the frame of ``voxels``.
        hand_faces: (F, 3) the hand's closed (watertight) faces.
        voxels: (N, 3) the object's surface voxel centres (:func:`surface_voxels`) at its pose.
        pitch: voxel size, m.

    Returns:
        (B,) penetration volumes, m^3 (a scalar array for a single hand).
    """
    hv = np.asarray(hand_vertices, dtype=np.float64)
    single = hv.ndim == 2
    hv = hv[None] if single else hv
    out = np.zeros(len(hv))
    for b, v in enumerate(hv):
        lo, hi = v.min(0) - pitch, v.max(0) + pitch
        near = voxels[np.all((voxels >= lo) & (voxels <= hi), axis=1)]
        if len(near):
            out[b] = occupancy(v, hand_faces, near).sum() * pitch**3
    return out[0] if single else out


def palm_gravity(palm_centres: np.ndarray, object_centre: np.ndarray, magnitude: float = 9.8) -> np.ndarray:
    """(B, 3) gravity vectors pulling the object away from each palm: ``magnitude`` along the unit vector
    from the (B, 3) palm centres to the object's centre (m/s^2)."""
    d = np.asarray(object_centre, dtype=np.float64) - np.asarray(palm_centres, dtype=np.float64)
    return magnitude * d / np.linalg.norm(d, axis=-1, keepdims=True).clip(1e-9)


def sd_gravity(settings: "SDSettings", palm_centres: np.ndarray, object_centre: np.ndarray) -> np.ndarray:
    """(B, 3) SD gravity per hand as ``settings.gravity_direction`` says: :func:`palm_gravity` from the
    (B, 3) palm centres through the object's centre (same frame), or the fixed ``settings.gravity``."""
    palm_centres = np.atleast_2d(palm_centres)
    if settings.gravity_direction == "away_from_palm":
        return palm_gravity(palm_centres, object_centre, float(np.linalg.norm(settings.gravity)))
    if settings.gravity_direction == "fixed":
        return np.broadcast_to(np.asarray(settings.gravity, dtype=np.float64), (len(palm_centres), 3))
    raise ValueError(f"metrics.sd.gravity_direction must be 'away_from_palm' or 'fixed', not {settings.gravity_direction!r}")


def contact_distance(hand_vertices: np.ndarray, object_mesh: trimesh.Trimesh) -> np.ndarray:
    """Smallest signed distance from the hand's vertices to the object's surface (negative inside), m.

    Args:
        hand_vertices: (B, V, 3) or (V, 3), metres, in the object mesh's frame.
        object_mesh: the watertight object.

    Returns:
        (B,) distances (a scalar array for a single hand).
    """
    hv = np.asarray(hand_vertices, dtype=np.float64)
    single = hv.ndim == 2
    hv = hv[None] if single else hv
    d = exact_signed_distance(object_mesh, hv.reshape(-1, 3)).reshape(hv.shape[:2])
    out = d.min(1)
    return out[0] if single else out


@dataclass(frozen=True)
class SDSettings:
    """The simulation-displacement protocol (SI units); defaults are the official evaluation code's."""

    gravity: tuple[float, float, float] = (0.0, 0.0, -9.8)
    gravity_direction: str = "away_from_palm"
    time_step: float = 1.0 / 240.0
    solver_iterations: int = 150
    steps: int = 35
    hand_friction: float = 3.0
    object_friction: float = 3.0
    object_mass: float = 1.0
    object_restitution: float = 0.5
    failed_displacement: float = 0.10


@dataclass
class DisplacementSimulator:
    """SD for many hands on one object: the object's collision parts are loaded once per world reset.

    Args:
        collision_obj: the object's convex decomposition (``collision.obj`` of the objects stage), in the
            object's mesh frame; in an objects folder (a ``meta.json`` beside it) it is checked against the
            checksum the stage recorded (``ValueError`` naming a damaged file).
        vertex_mean: (3,) the object's mesh vertex mean in that frame, m: its inertial frame for SD.
        settings: the protocol.
    """

    collision_obj: str | Path
    vertex_mean: np.ndarray
    settings: SDSettings = field(default_factory=SDSettings)

    def __post_init__(self) -> None:
        from tohgs.assets.manifest import META_JSON, check_object_file
        from tohgs.sim.client import DirectClient

        if (Path(self.collision_obj).parent / META_JSON).is_file():  # an objects folder: check its checksum
            check_object_file(self.collision_obj)
        self._client = DirectClient()

    def close(self) -> None:
        self._client.close()

    def __enter__(self) -> "DisplacementSimulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def displacement(self, hand_vertices: np.ndarray, hand_faces: np.ndarray,
                     object_pose: np.ndarray | None = None, gravity: np.ndarray | None = None,
                     solver_iterations: int | None = None) -> float:
        """SD of one hand, m.

        Args:
            hand_vertices: (V, 3) metres, world frame.
            hand_faces: (F, 3) hand triangles.
            object_pose: the object's mesh-frame pose ``[x, y, z, qx, qy, qz, qw]`` (default: identity).
            gravity: (3,) m/s^2 for this hand (default: the settings' ``gravity``).
            solver_iterations: this simulation's solver iterations (default: the settings'; robust SD's
                jitter, :func:`perturbed_displacements`).
        """
        pb, s, cid = self._client._pb, self.settings, self._client.cid
        g = np.asarray(s.gravity if gravity is None else gravity, dtype=np.float64)
        iterations = s.solver_iterations if solver_iterations is None else int(solver_iterations)
        try:
            self._client.reset_simulation(g.tolist(), s.time_step, iterations)
            hand_col = pb.createCollisionShape(pb.GEOM_MESH, vertices=np.asarray(hand_vertices, dtype=np.float64).tolist(),
                                               indices=np.asarray(hand_faces, dtype=np.int64).ravel().tolist(),
                                               flags=pb.GEOM_FORCE_CONCAVE_TRIMESH, physicsClientId=cid)
            hand = pb.createMultiBody(0, hand_col, physicsClientId=cid)
            pb.changeDynamics(hand, -1, lateralFriction=s.hand_friction, restitution=0.0, physicsClientId=cid)
            pos, orn = (np.zeros(3), np.array([0, 0, 0, 1.0])) if object_pose is None else (object_pose[:3], object_pose[3:])
            obj_col = pb.createCollisionShape(pb.GEOM_MESH, fileName=str(self.collision_obj), physicsClientId=cid)
            obj = pb.createMultiBody(s.object_mass, obj_col, basePosition=pos.tolist(), baseOrientation=orn.tolist(),
                                     baseInertialFramePosition=np.asarray(self.vertex_mean, dtype=np.float64).tolist(),
                                     physicsClientId=cid)
            pb.changeDynamics(obj, -1, lateralFriction=s.object_friction, restitution=s.object_restitution,
                              physicsClientId=cid)
            start = np.asarray(pb.getBasePositionAndOrientation(obj, physicsClientId=cid)[0])
            for _ in range(s.steps):
                pb.stepSimulation(physicsClientId=cid)
            end = np.asarray(pb.getBasePositionAndOrientation(obj, physicsClientId=cid)[0])
            d = float(np.linalg.norm(end - start))
            return d if np.isfinite(d) else s.failed_displacement
        except pb.error:
            return s.failed_displacement


@dataclass(frozen=True)
class RobustSDSettings:
    """SD under tiny perturbations of its start (:func:`perturbed_displacements`): ``perturbations``
    simulations per grasp (0: none), each with the hand moved by a random offset of at most ``offset`` (m,
    uniform in a ball) and the solver's iterations changed by a random integer in
    ``[-solver_jitter, solver_jitter]``; for the first ``grasps_per_config`` kept grasps of each
    configuration (0: all of them); drawn from ``seed`` and the grasp's identity, so that a grasp gets the
    same perturbations whatever else is evaluated with it."""

    perturbations: int = 0
    offset: float = 0.0005
    solver_jitter: int = 10
    grasps_per_config: int = 4
    seed: int = 0

    def __post_init__(self):
        if self.perturbations < 0 or self.offset < 0 or self.solver_jitter < 0 or self.grasps_per_config < 0:
            raise ValueError(f"robust SD settings must be non-negative, got {self}")


def perturbed_displacements(sim: DisplacementSimulator, hand_vertices: np.ndarray, hand_faces: np.ndarray,
                            settings: RobustSDSettings, rng: np.random.Generator,
                            object_pose: np.ndarray | None = None, gravity: np.ndarray | None = None) -> np.ndarray:
    """(K,) SD of one hand, m, under K = ``settings.perturbations`` perturbed starts: the protocol of
    :meth:`DisplacementSimulator.displacement` with the hand (V, 3) moved by a random offset in a ball of
    radius ``settings.offset`` and the solver's iterations jittered (:class:`RobustSDSettings`).

    The protocol's SD is one draw of a chaotic simulation for a marginal grasp (the same grasp can slip
    1 cm or 11 cm after a sub-millimetre change); the spread of these K values says how far to trust it."""
    k = settings.perturbations
    direction = rng.normal(size=(k, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True).clip(1e-12)
    radius = settings.offset * rng.random(k) ** (1.0 / 3.0)  # uniform in the ball
    jitter = rng.integers(-settings.solver_jitter, settings.solver_jitter + 1, k)
    base = sim.settings.solver_iterations
    hv = np.asarray(hand_vertices, dtype=np.float64)
    return np.array([sim.displacement(hv + radius[i] * direction[i], hand_faces, object_pose, gravity,
                                      solver_iterations=max(1, base + int(jitter[i]))) for i in range(k)])


IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # [x, y, z, qx, qy, qz, qw]


def hand_quality(hand_vertices: np.ndarray, faces: np.ndarray, palm_ids: np.ndarray, mesh: trimesh.Trimesh,
                 voxels: np.ndarray, sim: DisplacementSimulator, pitch: float = VOXEL_PITCH,
                 object_pose: np.ndarray | None = None, progress: bool = False,
                 robust: RobustSDSettings | None = None, robust_rngs: list[np.random.Generator] | None = None
                 ) -> dict[str, np.ndarray]:
    """PV (m^3), SD (m) and the contact distance (m) of S hands around one object: the one protocol the
    prior grasps and the evaluation share; with ``robust`` (perturbations > 0) also ``"sd_perturbed"``,
    (S, K) SDs under perturbed starts (:func:`perturbed_displacements`), NaN rows for the hands past
    ``robust.grasps_per_config``; ``robust_rngs`` one generator per hand.

    Args:
        hand_vertices: (S, V, 3) hands in the frame the object stands at ``object_pose`` in, m.
        faces: (F, 3) the hand's closed faces.
        palm_ids: the palm's vertex ids (SD's ``away_from_palm`` gravity pulls from the palm centre).
        mesh: the object's mesh (its own frame); ``voxels``: its surface voxels (:func:`surface_voxels`).
        sim: a simulator of the object (its collision parts and vertex mean), with the SD settings.
        object_pose: the object's ``[x, y, z, qx, qy, qz, qw]`` pose (default: its own frame).
    """
    pose = IDENTITY_POSE if object_pose is None else np.asarray(object_pose, dtype=np.float64)
    T = pose_matrix(pose)
    local = (hand_vertices - T[:3, 3]) @ T[:3, :3]  # PV and the contact distance in the mesh frame
    pv = np.atleast_1d(penetration_volume(local, faces, voxels, pitch))
    cd = np.atleast_1d(contact_distance(local, mesh))
    centre = T[:3, :3] @ np.asarray(sim.vertex_mean, dtype=np.float64) + T[:3, 3]
    gravity = sd_gravity(sim.settings, hand_vertices[:, palm_ids].mean(1), centre)
    it = range(len(hand_vertices))
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="SD", mininterval=5.0)
    sd = np.array([sim.displacement(hand_vertices[i], faces, object_pose=pose, gravity=gravity[i]) for i in it])
    out = {"pv": pv, "sd": sd, "contact_distance": cd}
    if robust is not None and robust.perturbations > 0:
        s = len(hand_vertices)
        if robust_rngs is None or len(robust_rngs) != s:
            got = None if robust_rngs is None else len(robust_rngs)
            raise ValueError(f"robust SD needs one generator per hand ({s}), got {got}")
        n = s if robust.grasps_per_config == 0 else min(s, robust.grasps_per_config)
        perturbed = np.full((s, robust.perturbations), np.nan)
        for i in range(n):
            perturbed[i] = perturbed_displacements(sim, hand_vertices[i], faces, robust, robust_rngs[i], pose,
                                                   gravity[i])
        out["sd_perturbed"] = perturbed
    return out
