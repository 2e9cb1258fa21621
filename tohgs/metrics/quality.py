"""Grasp quality metrics of the evaluation protocol, written once and reused by every stage.

- PV, penetration volume: the object at its pose voxelised at a 1 mm pitch (surface voxels, as trimesh's
  ``voxelized`` returns them); the voxel centres inside the closed hand mesh are counted, times the voxel
  volume. m^3 (tables report cm^3).
- SD, simulation displacement: PyBullet, the hand a static concave triangle mesh (its closed faces, or the
  decimated collision hand of ``evaluation.sd_hand``, :mod:`tohgs.hand.collision`; mass 0, friction 3,
  restitution 0); the object its convex decomposition, mass 1, friction 3, restitution 0.5, its inertial
  frame at the mesh's vertex mean; time step 1/240 s, 150 solver iterations, 35 steps (the official
  code's setting, not the paper's "1 s"); SD is how far the object's centre moved, m; a failed simulation
  counts 0.10 m. Gravity is a setting (``gravity_direction``): the official code applies it along +y of
  its camera-derived frame, which has no meaning for tohgs's grasps. ``"away_from_palm"`` (the default)
  pulls the object from the palm centre through the object's centre: the direction it is lifted against
  when the hand approaches from the free side of its support (a table top, a shelf board), whatever
  orientation the object rests in; ``"fixed"`` uses the ``gravity`` vector of the grasp's frame (for
  grasps in the world frame, -z). Many hands: :meth:`DisplacementSimulator.displacements` runs the same
  protocol per hand, bit for bit, in ``workers`` processes (nearly all of SD's time is PyBullet's contact
  detection and solver, the protocol's physics itself; docs/stages.md, "Where SD's time goes").
- Robust SD (beyond the protocol): SD again under K tiny perturbations of the start (the hand moved by at
  most half a millimetre, the solver's iterations jittered), for a few grasps per configuration
  (:class:`RobustSDSettings`); the protocol's single SD stays the paper's QR.
- Contact: PV > 0, and separately the smallest signed distance from the hand's vertices to the object's
  surface (negative inside), m.
"""

from __future__ import annotations

import logging
import math
import multiprocessing as mp
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
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


class SDWorkers:
    """Worker processes that simulate SD, shared by the simulators of a job (a worker keeps a simulator of
    each of the last few objects it was given).

    PyBullet keeps about 0.6 MB per simulated hand until its process ends (``resetSimulation`` and
    ``disconnect`` do not free it), so the workers are replaced by fresh processes once they have simulated
    ``recycle_after`` hands (between two calls). Forked on first use, ended by :meth:`close`.

    Args:
        workers: processes (a job's cores, Snakemake's ``threads``).
        recycle_after: hands before the workers are replaced.
    """

    def __init__(self, workers: int = 1, recycle_after: int = 500) -> None:
        if int(workers) < 1 or int(recycle_after) < 1:
            raise ValueError(f"SD needs at least one worker and recycle_after >= 1, got workers={workers}, "
                             f"recycle_after={recycle_after}")
        self.workers, self.recycle_after = int(workers), int(recycle_after)
        self._pool: ProcessPoolExecutor | None = None
        self._hands = 0  # hands the current processes have simulated

    def close(self) -> None:
        """End the worker processes."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def __enter__(self) -> "SDWorkers":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def displacements(self, collision_obj: str | Path, vertex_mean: np.ndarray, settings: SDSettings, hv: np.ndarray,
                      faces: np.ndarray, object_pose: np.ndarray | None, gravity: np.ndarray | None,
                      iterations: np.ndarray | None, bar=None) -> np.ndarray:
        """(B,) SD of the (B, V, 3) hands ``hv`` by :meth:`DisplacementSimulator.displacement` of a simulator
        of the object (``collision_obj``, ``vertex_mean``, ``settings``) in the workers: the hands in
        contiguous chunks (about four per worker, so that a slow chunk does not hold the others up), put back
        in order; ``gravity`` (B, 3) and ``iterations`` (B,) per hand or None (the settings'); ``bar`` a
        progress bar to advance."""
        b = len(hv)
        if self._pool is not None and self._hands >= self.recycle_after:
            self._pool.shutdown()  # fresh processes give back the memory PyBullet kept
            self._pool = None
        if self._pool is None:
            # fork, not spawn: spawn re-runs the parent's __main__ (a Snakemake script) in each worker.
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("fork"))
            self._hands = 0
        self._hands += b
        size = max(1, math.ceil(b / (4 * self.workers)))
        starts = range(0, b, size)
        mean = np.asarray(vertex_mean, dtype=np.float64)
        futures: list[Future] = [
            self._pool.submit(_displacement_chunk, str(collision_obj), mean, settings, hv[a:a + size], faces, object_pose,
                              None if gravity is None else gravity[a:a + size],
                              None if iterations is None else iterations[a:a + size])
            for a in starts]
        out = np.empty(b)
        try:
            for a, future in zip(starts, futures):
                chunk = future.result()
                out[a:a + len(chunk)] = chunk
                if bar is not None:
                    bar.update(len(chunk))
        except BrokenProcessPool as exc:
            from tohgs.sim.isolation import SimulationCrash

            self._pool = None
            raise SimulationCrash(f"an SD worker process died while simulating hands on {collision_obj}; "
                                  "see the log for the native stack") from exc
        return out


@dataclass
class DisplacementSimulator:
    """SD for many hands on one object.

    :meth:`displacement` is the protocol for one hand, the reference: a fresh world per hand (reset, the
    hand's triangle mesh, the object's collision parts parsed from ``collision_obj``, 35 steps), in this
    process. :meth:`displacements` gives the same SD for a batch of hands, bit for bit, from worker
    processes (:class:`SDWorkers`) that each run :meth:`displacement` on their share.

    Args:
        collision_obj: the object's convex decomposition (``collision.obj`` of the objects stage), in the
            object's mesh frame; in an objects folder (a ``meta.json`` beside it) it is checked against the
            checksum the stage recorded (``ValueError`` naming a damaged file).
        vertex_mean: (3,) the object's mesh vertex mean in that frame, m: its inertial frame for SD.
        settings: the protocol.
        workers: the processes of :meth:`displacements`: a number (this simulator's own
            :class:`SDWorkers`, ended by :meth:`close`) or an :class:`SDWorkers` shared with the job's
            other simulators (its owner ends it).
    """

    collision_obj: str | Path
    vertex_mean: np.ndarray
    settings: SDSettings = field(default_factory=SDSettings)
    workers: int | SDWorkers = 1

    def __post_init__(self) -> None:
        from tohgs.assets.manifest import META_JSON, check_object_file
        from tohgs.sim.client import DirectClient

        if (Path(self.collision_obj).parent / META_JSON).is_file():  # an objects folder: check its checksum
            check_object_file(self.collision_obj)
        self._own = not isinstance(self.workers, SDWorkers)
        self._workers = SDWorkers(self.workers) if self._own else self.workers
        self._client = DirectClient()

    def close(self) -> None:
        """Disconnect the client and end the worker processes if they are this simulator's own."""
        if self._own:
            self._workers.close()
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

    def displacements(self, hand_vertices: np.ndarray, hand_faces: np.ndarray, object_pose: np.ndarray | None = None,
                      gravity: np.ndarray | None = None, solver_iterations: np.ndarray | None = None,
                      progress: bool = False) -> np.ndarray:
        """SD of B hands, m: :meth:`displacement` of each, the same numbers bit for bit, in the worker
        processes (each hand is simulated alone in a freshly reset world, so which process simulates it, and
        after which other hands, does not change its SD).

        Args:
            hand_vertices: (B, V, 3) metres, world frame.
            hand_faces: (F, 3) hand triangles.
            object_pose: the object's mesh-frame pose ``[x, y, z, qx, qy, qz, qw]`` (default: identity).
            gravity: (B, 3) or (3,) m/s^2 (default: the settings' ``gravity``).
            solver_iterations: (B,) solver iterations per hand (default: the settings').
            progress: show a progress bar over the hands.

        Returns:
            (B,) SD, m (``settings.failed_displacement`` for a failed simulation).
        """
        hv = np.asarray(hand_vertices, dtype=np.float64)
        if hv.ndim != 3 or hv.shape[-1] != 3:
            raise ValueError(f"hand_vertices must have shape (B, V, 3), got {hv.shape}")
        b = len(hv)
        g = None if gravity is None else np.broadcast_to(np.asarray(gravity, dtype=np.float64), (b, 3))
        iters = (None if solver_iterations is None else
                 np.broadcast_to(np.asarray(solver_iterations, dtype=np.int64), (b,)))
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=b, desc="SD", mininterval=5.0)
        try:
            return self._workers.displacements(self.collision_obj, self.vertex_mean, self.settings, hv,
                                               np.asarray(hand_faces), object_pose, g, iters, bar)
        finally:
            if bar is not None:
                bar.close()


#: Each worker process's simulators, by object and protocol, the most recently used last
#: (:func:`_displacement_chunk`).
_WORKER_SIMULATORS: dict[tuple, DisplacementSimulator] = {}
_WORKER_KEEP = 4  # simulators a worker keeps (a job's objects come one after another)


def _displacement_chunk(collision_obj: str, vertex_mean: np.ndarray, settings: SDSettings, hands: np.ndarray,
                        faces: np.ndarray, object_pose: np.ndarray | None, gravity: np.ndarray | None,
                        iterations: np.ndarray | None) -> np.ndarray:
    """(C,) SD of C hands (C, V, 3) in a worker process: :meth:`DisplacementSimulator.displacement` of each,
    on a simulator of the object kept for the worker's next chunks; ``gravity`` (C, 3) and ``iterations``
    (C,) per hand or None (the settings')."""
    import faulthandler

    faulthandler.enable()  # a native crash leaves its stack in the job's log
    key = (collision_obj, vertex_mean.tobytes(), repr(settings))
    sim = _WORKER_SIMULATORS.pop(key, None)
    if sim is None:
        sim = DisplacementSimulator(collision_obj, vertex_mean, settings)
        while len(_WORKER_SIMULATORS) >= _WORKER_KEEP:
            _WORKER_SIMULATORS.pop(next(iter(_WORKER_SIMULATORS))).close()
    _WORKER_SIMULATORS[key] = sim
    return np.array([sim.displacement(hands[i], faces, object_pose, None if gravity is None else gravity[i],
                                      None if iterations is None else int(iterations[i])) for i in range(len(hands))],
                    dtype=np.float64)


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


def perturbed_starts(hand_vertices: np.ndarray, settings: RobustSDSettings, rng: np.random.Generator,
                     solver_iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """The K = ``settings.perturbations`` perturbed starts of one hand (:class:`RobustSDSettings`): (K, V, 3)
    the (V, 3) hand moved by random offsets in a ball of radius ``settings.offset`` (m), and (K,) the
    protocol's ``solver_iterations`` jittered (at least 1), drawn from ``rng`` in that order."""
    k = settings.perturbations
    direction = rng.normal(size=(k, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True).clip(1e-12)
    radius = settings.offset * rng.random(k) ** (1.0 / 3.0)  # uniform in the ball
    jitter = rng.integers(-settings.solver_jitter, settings.solver_jitter + 1, k)
    hv = np.asarray(hand_vertices, dtype=np.float64)
    hands = hv[None] + (radius[:, None] * direction)[:, None, :]
    return hands, np.maximum(1, int(solver_iterations) + jitter)


def perturbed_displacements(sim: DisplacementSimulator, hand_vertices: np.ndarray, hand_faces: np.ndarray,
                            settings: RobustSDSettings, rng: np.random.Generator,
                            object_pose: np.ndarray | None = None, gravity: np.ndarray | None = None) -> np.ndarray:
    """(K,) SD of one hand, m, under K = ``settings.perturbations`` perturbed starts: the protocol of
    :meth:`DisplacementSimulator.displacement` with the hand (V, 3) moved by a random offset in a ball of
    radius ``settings.offset`` and the solver's iterations jittered (:func:`perturbed_starts`).

    The protocol's SD is one draw of a chaotic simulation for a marginal grasp (the same grasp can slip
    1 cm or 11 cm after a sub-millimetre change); the spread of these K values says how far to trust it."""
    hands, iterations = perturbed_starts(hand_vertices, settings, rng, sim.settings.solver_iterations)
    return sim.displacements(hands, hand_faces, object_pose, gravity, iterations)


IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # [x, y, z, qx, qy, qz, qw]


def hand_quality(hand_vertices: np.ndarray, faces: np.ndarray, palm_ids: np.ndarray, mesh: trimesh.Trimesh,
                 voxels: np.ndarray, sim: DisplacementSimulator, pitch: float = VOXEL_PITCH,
                 object_pose: np.ndarray | None = None, progress: bool = False,
                 robust: RobustSDSettings | None = None, robust_rngs: list[np.random.Generator] | None = None,
                 sd_mesh: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """PV (m^3), SD (m) and the contact distance (m) of S hands around one object: the one protocol the
    prior grasps and the evaluation share; with ``robust`` (perturbations > 0) also ``"sd_perturbed"``,
    (S, K) SDs under perturbed starts (:func:`perturbed_displacements`), NaN rows for the hands past
    ``robust.grasps_per_config``; ``robust_rngs`` one generator per hand.

    Args:
        hand_vertices: (S, V, 3) hands in the frame the object stands at ``object_pose`` in, m.
        faces: (F, 3) the hand's closed faces.
        palm_ids: the palm's vertex ids (SD's ``away_from_palm`` gravity pulls from the palm centre).
        mesh: the object's mesh (its own frame); ``voxels``: its surface voxels (:func:`surface_voxels`).
        sim: a simulator of the object (its collision parts and vertex mean), with the SD settings; the S
            hands (and the robust starts, another batch) go to :meth:`DisplacementSimulator.displacements`,
            so its ``workers`` share them.
        object_pose: the object's ``[x, y, z, qx, qy, qz, qw]`` pose (default: its own frame).
        progress: show a progress bar over the hands' SD.
        sd_mesh: ``(vertices, faces)`` that SD (and robust SD) simulates instead of the hand's: (S, V', 3)
            the same S hands as another mesh, m (a :class:`tohgs.hand.collision.CollisionHand` posed from
            ``hand_vertices``), and its (F', 3) faces; PV, the contact distance and the gravity's palm centre
            keep the full hand. None: SD simulates ``hand_vertices`` and ``faces``.
    """
    pose = IDENTITY_POSE if object_pose is None else np.asarray(object_pose, dtype=np.float64)
    T = pose_matrix(pose)
    local = (hand_vertices - T[:3, 3]) @ T[:3, :3]  # PV and the contact distance in the mesh frame
    pv = np.atleast_1d(penetration_volume(local, faces, voxels, pitch))
    cd = np.atleast_1d(contact_distance(local, mesh))
    centre = T[:3, :3] @ np.asarray(sim.vertex_mean, dtype=np.float64) + T[:3, 3]
    gravity = sd_gravity(sim.settings, hand_vertices[:, palm_ids].mean(1), centre)
    sd_vertices, sd_faces = (hand_vertices, faces) if sd_mesh is None else sd_mesh
    if len(sd_vertices) != len(hand_vertices):
        raise ValueError(f"sd_mesh must hold the same {len(hand_vertices)} hands, got {len(sd_vertices)}")
    sd = sim.displacements(sd_vertices, sd_faces, pose, gravity, progress=progress)
    out = {"pv": pv, "sd": sd, "contact_distance": cd}
    if robust is not None and robust.perturbations > 0:
        s, k = len(hand_vertices), robust.perturbations
        if robust_rngs is None or len(robust_rngs) != s:
            got = None if robust_rngs is None else len(robust_rngs)
            raise ValueError(f"robust SD needs one generator per hand ({s}), got {got}")
        n = s if robust.grasps_per_config == 0 else min(s, robust.grasps_per_config)
        perturbed = np.full((s, k), np.nan)
        if n:  # the n hands' K starts each, simulated as one batch (:func:`perturbed_displacements` per hand)
            starts = [perturbed_starts(sd_vertices[i], robust, robust_rngs[i], sim.settings.solver_iterations)
                      for i in range(n)]
            sds = sim.displacements(np.concatenate([h for h, _ in starts]), sd_faces, pose,
                                    np.repeat(gravity[:n], k, axis=0), np.concatenate([it for _, it in starts]))
            perturbed[:n] = sds.reshape(n, k)
        out["sd_perturbed"] = perturbed
    return out
