"""The prior-grasp stage: synthesise grasps of one object, measure them, and filter them.

Two steps, two workflow rules, so that a threshold change reruns only the cheap one:

1. :func:`make_prior_grasps`: the object's SDF grid (content-addressed cache), the annealing optimiser
   (:mod:`tohgs.grasps.synthesis`), then PV and the contact distance of every grasp and SD of the grasps
   that pass the filter's energy and joint-limit checks (or of every grasp without a screen)
   (:mod:`tohgs.metrics.quality`) -> the raw store.
2. :func:`~tohgs.grasps.filter.filter_prior_grasps`: the filter's flags -> the filtered store (numpy only:
   the joint limits travel in the raw store, so the filter job imports no torch).

The stage's summary, :func:`~tohgs.grasps.filter.summarize_prior_grasps`, is torch-free too.
"""

from __future__ import annotations

import logging
import time
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import trimesh

from tohgs.assets.mesh import OBJECT_MESH, object_mesh
from tohgs.data.grasps import ENERGY_TERMS, PriorGrasps, write_prior_grasps
from tohgs.geometry.sdf import SDFGrid
from tohgs.grasps.filter import (SCREEN_KEYS, FilterThresholds, filter_prior_grasps,  # noqa: F401  (re-exported: the stage's other steps)
                                 screen_flags, summarize_prior_grasps)
from tohgs.grasps.synthesis import SynthesisSettings, rest_directions, synthesize
from tohgs.hand.model import HandModel
from tohgs.cache import load_or_compute
from tohgs.io import content_key
from tohgs.runtime import keep_freed_memory
from tohgs.settings import settings_from
from tohgs.metrics.quality import (DisplacementSimulator, SDSettings, contact_distance, hand_quality, penetration_volume,
                                   surface_voxels)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SDFSettings:
    """The object's signed-distance grid: ``spacing`` and ``padding`` beyond its bounds, m."""

    spacing: float = 0.002
    padding: float = 0.05


def object_sdf(mesh: trimesh.Trimesh, settings: SDFSettings, cache_dir: str | Path | None = None) -> SDFGrid:
    """The SDF grid of ``mesh``, cached under ``<cache_dir>/sdf/<key>.npz`` (keyed by the mesh's vertices
    and faces and the settings)."""
    key = content_key(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), asdict(settings))
    grid, _ = load_or_compute(cache_dir, "sdf", key, ".npz", lambda: SDFGrid.build(mesh, settings.spacing, settings.padding),
                              lambda g, path: g.save(path), SDFGrid.load)
    return grid


def object_seed(seed: int, name: str) -> int:
    """The synthesis seed of one object: independent of the other objects and of the job order."""
    return int(np.random.SeedSequence([int(seed), zlib.crc32(name.encode())]).generate_state(1)[0])


def evaluate_grasps(hand: HandModel, pose: np.ndarray, mesh: trimesh.Trimesh, collision_obj: str | Path,
                    sd_settings: SDSettings, voxel_pitch: float = 0.001, progress: bool = False,
                    cache_dir: str | Path | None = None, simulate: np.ndarray | None = None,
                    voxels: np.ndarray | None = None, workers: int = 1) -> dict[str, np.ndarray]:
    """PV (m^3), SD (m) and contact distance (m) of (B, 51) grasps of one object in its mesh frame; SD's
    gravity per grasp as ``sd_settings.gravity_direction`` says (:func:`tohgs.metrics.quality.palm_gravity` by default); the
    object's surface voxels are cached under ``cache_dir``.

    ``simulate``: (B,) bool, the grasps whose SD is simulated (None: all); the others get SD NaN. Each
    grasp's metrics are its own (one PyBullet world reset per grasp), so a grasp measures the same with or
    without the others. ``voxels``: the object's surface voxels if already at hand (else
    :func:`~tohgs.metrics.quality.surface_voxels`). SD runs in ``workers`` processes (the same numbers as
    one, :meth:`tohgs.metrics.quality.DisplacementSimulator.displacements`)."""
    with torch.no_grad():
        verts = hand(torch.as_tensor(pose, dtype=hand.rest_vertices.dtype)).vertices.cpu().numpy().astype(np.float64)
    faces = hand.closed_faces.cpu().numpy()
    voxels = surface_voxels(mesh, voxel_pitch, cache_dir) if voxels is None else voxels
    sim_rows = np.ones(len(verts), dtype=bool) if simulate is None else np.asarray(simulate, dtype=bool)
    out = {"pv": np.zeros(len(verts)), "sd": np.full(len(verts), np.nan), "contact_distance": np.zeros(len(verts))}
    if sim_rows.any():
        centre = np.asarray(mesh.vertices).mean(0)
        with DisplacementSimulator(collision_obj, centre, sd_settings, workers=workers) as sim:
            measured = hand_quality(verts[sim_rows], faces, hand.assets.palm_ids, mesh, voxels, sim, voxel_pitch,
                                    progress=progress)
        for k in out:
            out[k][sim_rows] = measured[k]
    if not sim_rows.all():
        rest = verts[~sim_rows]
        out["pv"][~sim_rows] = penetration_volume(rest, faces, voxels, voxel_pitch)
        out["contact_distance"][~sim_rows] = contact_distance(rest, mesh)
    return out


def make_prior_grasps(object_dir: str | Path, hand: HandModel, hand_name: str, synthesis: dict[str, Any],
                      sdf: dict[str, Any], sd: dict[str, Any], voxel_pitch: float, plane_direction: str,
                      seed: int, out: str | Path, cache_dir: str | Path | None = None, threads: int = 1,
                      screen: dict[str, Any] | None = None) -> PriorGrasps:
    """Synthesise and measure the prior grasps of the object in ``object_dir``; write the raw store.

    Args:
        object_dir: the objects stage's folder (``mesh.obj``, ``collision.obj``, ``meta.json``).
        hand: the hand model; ``hand_name`` is recorded.
        synthesis, sdf, sd: config mappings of :class:`SynthesisSettings`, :class:`SDFSettings` and
            :class:`~tohgs.metrics.quality.SDSettings`.
        voxel_pitch: PV's voxel size, m.
        plane_direction: ``"stable"``, ``"random"`` or ``"down"``, see :func:`support_planes`.
        seed: the global seed (combined with the object's name).
        out: the raw store to write.
        cache_dir: cache root for SDF grids and surface voxels (None: no cache).
        threads: the job's cores: torch threads of the synthesis, then SD's worker processes.
        screen: the filter's thresholds of the checks that need no metric (:data:`~tohgs.grasps.filter.SCREEN_KEYS`,
            a config mapping): SD is simulated only for the grasps that pass them
            (:func:`~tohgs.grasps.filter.screen_flags`), NaN for the others, and the store records them
            (attribute ``screen``). None: every grasp is simulated.
    """
    torch.set_num_threads(max(1, int(threads)))
    keep_freed_memory()  # the optimiser's megabyte tensors would otherwise page-fault in every step
    object_dir = Path(object_dir)
    name = object_dir.name
    mesh = object_mesh(object_dir.parent, name)
    if not mesh.is_watertight:
        raise ValueError(f"{object_dir / OBJECT_MESH}: the object mesh is not watertight (SDF and PV need a closed surface)")
    s_syn = settings_from(SynthesisSettings, {**synthesis, "plane_direction": plane_direction})
    s_sdf = settings_from(SDFSettings, sdf)
    s_sd = settings_from(SDSettings, sd)
    timing, cpu_timing = {}, {}  # seconds per phase: wall clock, and this process's CPU time
    t0, c0 = time.perf_counter(), time.process_time()
    grid = object_sdf(mesh, s_sdf, cache_dir)
    timing["sdf"], cpu_timing["sdf"] = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    rest = rest_directions(mesh) if s_syn.plane_direction == "stable" else None
    result = synthesize(hand, grid, mesh.vertices, s_syn, object_seed(seed, name), progress=True, rest=rest)
    timing["synthesis"], cpu_timing["synthesis"] = time.perf_counter() - t0, time.process_time() - c0
    log.info("%s: %d grasps, mean energy %.3f -> %.3f in %.1f s", name, s_syn.batch, result.history[0],
             result.history[-1], timing["synthesis"])
    t0, c0 = time.perf_counter(), time.process_time()
    voxels = surface_voxels(mesh, voxel_pitch, cache_dir)
    timing["voxels"], cpu_timing["voxels"] = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    pose = result.pose.cpu().numpy()
    e = result.energies
    simulate, screened = None, None
    if screen is not None:
        unknown = set(screen) - set(SCREEN_KEYS)
        if unknown:
            raise ValueError(f"screen: only {list(SCREEN_KEYS)} can screen grasps before SD, not {sorted(unknown)}")
        t_screen = settings_from(FilterThresholds, screen)
        screened = {k: float(getattr(t_screen, k)) for k in SCREEN_KEYS}
        simulate = screen_flags(pose[:, 6:], hand.joint_limits.cpu().numpy(), e.fc.cpu().numpy(), e.dis.cpu().numpy(),
                                e.pen.cpu().numpy(), t_screen)
        log.info("%s: %d of %d grasps pass the energy and joint-limit checks; SD simulates only those", name,
                 int(simulate.sum()), len(simulate))
    metrics = evaluate_grasps(hand, pose, mesh, object_dir / "collision.obj", s_sd, voxel_pitch, progress=True,
                              cache_dir=cache_dir, simulate=simulate, voxels=voxels, workers=threads)
    timing["metrics"], cpu_timing["metrics"] = time.perf_counter() - t0, time.process_time() - c0
    sd = metrics["sd"][np.isfinite(metrics["sd"])]
    log.info("%s: PV median %.2f cm^3, SD median %.2f cm (%d simulated), metrics in %.1f s", name,
             float(np.median(metrics["pv"])) * 1e6, float(np.median(sd)) * 100 if len(sd) else float("nan"), len(sd),
             timing["metrics"])
    grasps = PriorGrasps(
        object=name, pose=pose, contact_idx=result.contact_idx.cpu().numpy(), plane=result.planes.cpu().numpy(),
        energies={k: getattr(e, k).cpu().numpy() for k in ENERGY_TERMS}, **metrics,
        attrs={"hand": hand_name, "joint_limits": hand.joint_limits.cpu().numpy().tolist(), "seed": int(seed), "timing": timing,
               "cpu_timing": cpu_timing,
               "screen": screened, "history": result.history[:: max(1, len(result.history) // 100)],
               "config": {"synthesis": asdict(s_syn), "sdf": asdict(s_sdf), "sd": asdict(s_sd), "voxel_pitch": voxel_pitch}})
    write_prior_grasps(grasps, out)
    return grasps
