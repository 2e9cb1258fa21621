"""The batched SD (:meth:`DisplacementSimulator.displacements`, in-process and in worker processes) against
the reference protocol (:meth:`DisplacementSimulator.displacement`, one hand at a time), bit for bit."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers import prepare_small_object
from tohgs.assets.sources import ObjectSpec
from tohgs.hand import load_hand_assets
from tohgs.metrics.quality import (DisplacementSimulator, RobustSDSettings, SDSettings, SDWorkers, contact_distance,
                                   hand_quality, perturbed_starts, sd_gravity, surface_voxels)
from tohgs.sim.isolation import SimulationCrash

POSE = np.array([0.3, -0.2, 0.75, 0.0, 0.0, np.sin(0.3), np.cos(0.3)])  # the object's world pose
PAPER_GRAVITY = (0.0, 9.8, 0.0)  # the official code's fixed world-frame gravity


@pytest.fixture(scope="module")
def u_brick(tmp_path_factory):
    """The objects stage's U brick (its CoACD parts in ``collision.obj``), its mesh and vertex mean."""
    import trimesh

    out = tmp_path_factory.mktemp("objects") / "brick-u-shape"
    meta = prepare_small_object(ObjectSpec("brick-u-shape", "bricks", "stacking", None, "u-shape"), out, None)
    assert meta["n_collision_parts"] >= 2  # a multi-part compound, the case the default objects are
    mesh = trimesh.load(out / "mesh.obj", force="mesh", process=False)
    return out / "collision.obj", mesh, np.asarray(mesh.vertices).mean(0)


@pytest.fixture(scope="module")
def hands(u_brick):
    """(S, V, 3) hands on the brick at :data:`POSE`, alternately a relaxed hand closed around it (its
    fingertips' and palm's centre within 1.5 cm of the brick's centre, turned at random: it holds it) and a
    pinch whose palm faces the brick from a random direction, 3 mm into it to 3 mm clear (it slips or
    misses); the closed faces, the palm ids and the brick's world-frame vertex mean."""
    import trimesh

    _, mesh, centre = u_brick
    assets = load_hand_assets("anny")
    rng = np.random.default_rng(0)
    relaxed, pinch = assets.vertices(np.stack([assets.presets["relaxed"], assets.presets["pinch"]]))
    grip = np.concatenate([relaxed[assets.tip_ids], relaxed[assets.palm_ids]]).mean(0)
    palm = pinch[assets.palm_ids].mean(0)
    facing = trimesh.Trimesh(pinch, assets.closed_faces, process=False).vertex_normals[assets.palm_ids].mean(0)
    out = []
    for k in range(10):  # in the brick's mesh frame
        if k % 2 == 0:
            out.append(Rotation.random(random_state=rng).apply(relaxed - grip) + centre + rng.uniform(-0.015, 0.015, 3))
            continue
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        turn = Rotation.from_rotvec(u * rng.uniform(0, 2 * np.pi)) * Rotation.align_vectors([-u], [facing])[0]
        hand = turn.apply(pinch - palm) + centre + ((mesh.vertices - centre) @ u).max() * u
        gap = rng.uniform(-0.003, 0.003)  # the hand's closest vertex to the brick
        for _ in range(3):  # moved along u, not the surface normal: a few corrections
            hand = hand - (contact_distance(hand, mesh) - gap) * u
        out.append(hand)
    world = Rotation.from_quat(POSE[3:])
    return (world.apply(np.concatenate(out)).reshape(len(out), -1, 3) + POSE[:3], np.asarray(assets.closed_faces),
            np.asarray(assets.palm_ids), world.apply(centre) + POSE[:3])


@pytest.mark.parametrize("direction", ["fixed", "away_from_palm"])
def test_batched_sd_equals_the_one_hand_protocol_bit_for_bit(u_brick, hands, direction):
    path, _, centre = u_brick
    verts, faces, palm, world_centre = hands
    settings = SDSettings(gravity_direction=direction, gravity=PAPER_GRAVITY)
    gravity = sd_gravity(settings, verts[:, palm].mean(1), world_centre)
    with DisplacementSimulator(path, centre, settings) as sim:
        reference = np.array([sim.displacement(v, faces, POSE, g) for v, g in zip(verts, gravity)])
        one_worker = sim.displacements(verts, faces, POSE, gravity)
    with DisplacementSimulator(path, centre, settings, workers=2) as sim:
        pooled = sim.displacements(verts, faces, POSE, gravity)
        again = sim.displacements(verts[::-1], faces, POSE, gravity[::-1])  # other chunks, other order
    # a set of grasps that tells SDs apart: some held (under QR's 2 cm), some lost
    assert (reference < 0.02).sum() >= 2 and (reference > 0.02).sum() >= 2, reference
    np.testing.assert_array_equal(one_worker, reference)
    np.testing.assert_array_equal(pooled, reference)
    np.testing.assert_array_equal(again[::-1], reference)


def test_robust_sd_in_one_batch_equals_each_start_simulated_alone(u_brick, hands):
    path, mesh, centre = u_brick
    verts, faces, palm, world_centre = hands
    settings = SDSettings(gravity_direction="fixed", gravity=PAPER_GRAVITY)
    robust = RobustSDSettings(perturbations=2, grasps_per_config=3, offset=0.0005, solver_jitter=10)
    voxels = surface_voxels(mesh)
    with DisplacementSimulator(path, centre, settings, workers=2) as sim:
        q = hand_quality(verts[:4], faces, palm, mesh, voxels, sim, object_pose=POSE, robust=robust,
                         robust_rngs=[np.random.default_rng([7, k]) for k in range(4)])
        reference = np.full((4, 2), np.nan)
        for k in range(3):
            starts, iterations = perturbed_starts(verts[k], robust, np.random.default_rng([7, k]),
                                                  settings.solver_iterations)
            reference[k] = [sim.displacement(h, faces, POSE, np.array(PAPER_GRAVITY), int(n))
                            for h, n in zip(starts, iterations)]
        protocol = [sim.displacement(v, faces, POSE, np.array(PAPER_GRAVITY)) for v in verts[:4]]
    assert not np.array_equal(iterations, [settings.solver_iterations] * 2)  # the jitter is exercised
    np.testing.assert_array_equal(q["sd_perturbed"], reference)
    np.testing.assert_array_equal(q["sd"], protocol)


def test_workers_shared_by_two_objects_and_replaced_after_recycle_after_hands_give_the_same_sd(u_brick, hands,
                                                                                              tmp_path):
    import trimesh

    path, _, centre = u_brick
    verts, faces, _, _ = hands
    cube = tmp_path / "collision.obj"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(cube)  # a second object, one part
    cube_pose = POSE + np.r_[0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0]
    with SDWorkers(workers=1, recycle_after=5) as workers:
        with DisplacementSimulator(path, centre, workers=workers) as brick, \
                DisplacementSimulator(cube, np.zeros(3), workers=workers) as box:
            first = brick.displacements(verts[:3], faces, POSE)
            pool = workers._pool  # the processes of the first hands
            on_box = box.displacements(verts[:3], faces, cube_pose)  # 6 hands: still the same processes
            assert workers._pool is pool
            second = brick.displacements(verts[:3], faces, POSE)
            assert workers._pool is not pool  # past recycle_after: fresh processes (PyBullet's memory back)
            reference = [brick.displacement(v, faces, POSE) for v in verts[:3]]
            reference_box = [box.displacement(v, faces, cube_pose) for v in verts[:3]]
        assert workers._pool is not None  # a shared pool outlives its simulators; its owner ends it
    assert workers._pool is None
    np.testing.assert_array_equal(first, reference)
    np.testing.assert_array_equal(second, reference)
    np.testing.assert_array_equal(on_box, reference_box)
    assert not np.array_equal(on_box, first)


def _die(*args, **kwargs):
    """A chunk that kills its worker process, as a native crash would."""
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_dead_worker_is_a_clear_error_and_bad_arguments_are_refused(u_brick, hands, monkeypatch):
    path, _, centre = u_brick
    verts, faces, _, _ = hands
    with pytest.raises(ValueError, match="at least one worker"):
        DisplacementSimulator(path, centre, workers=0)
    with pytest.raises(ValueError, match="recycle_after >= 1"):
        SDWorkers(2, recycle_after=0)
    with DisplacementSimulator(path, centre, workers=2) as sim:
        with pytest.raises(ValueError, match=r"shape \(B, V, 3\)"):
            sim.displacements(verts[0], faces)
        monkeypatch.setattr("tohgs.metrics.quality._displacement_chunk", _die)
        with pytest.raises(SimulationCrash, match="SD worker process died"):
            sim.displacements(verts[:4], faces, POSE)
