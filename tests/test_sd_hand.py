"""SD's collision hand (:mod:`tohgs.hand.collision`, ``evaluation.sd_hand``): the decimated hand's triangle
count, its exact posing by the barycentric map, its cache, the setting's validation, and SD with it on a
held grasp against the full hand's."""

from __future__ import annotations

import copy
import logging

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from helpers import prepare_small_object
from tohgs.assets.sources import ObjectSpec
from tohgs.config import ConfigError, load_schema, validate_config
from tohgs.geometry.scene import SceneCollider
from tohgs.hand import load_hand_assets
from tohgs.hand.collision import MIN_TRIANGLES, CollisionHand, build_collision_hand, collision_hand, sd_hand_of
from tohgs.metrics.evaluate import _ObjectAssets, grasp_metrics
from tohgs.metrics.quality import DisplacementSimulator, SDSettings, hand_quality, palm_gravity, surface_voxels
from tohgs.settings import merge

POSE = np.array([0.3, -0.2, 0.75, 0.0, 0.0, np.sin(0.3), np.cos(0.3)])  # the object's world pose
PAPER_GRAVITY = (0.0, 9.8, 0.0)  # the official code's fixed world-frame gravity


@pytest.fixture(scope="module")
def hand():
    return load_hand_assets("anny")


@pytest.fixture(scope="module")
def collision_1600(hand):
    return build_collision_hand(hand.rest_vertices, hand.closed_faces, 1600)


def _random_grasps(hand, n: int, seed: int) -> np.ndarray:
    """(n, 51) grasps: the presets with noise on the finger joints, turned and moved at random."""
    rng = np.random.default_rng(seed)
    names = sorted(hand.presets)
    g = np.stack([hand.presets[names[k % len(names)]] for k in range(n)]).astype(np.float64)
    g[:, 6:] += rng.normal(0.0, 0.15, (n, 45))
    g[:, 3:6] = Rotation.random(n, random_state=rng).as_rotvec()
    g[:, :3] = rng.uniform(-0.5, 0.5, (n, 3))
    return g


@pytest.mark.parametrize("triangles", [1600, 800, MIN_TRIANGLES])
def test_the_collision_hand_has_the_asked_triangles_and_poses_on_the_full_surface(hand, triangles):
    ch = build_collision_hand(hand.rest_vertices, hand.closed_faces, triangles)
    assert abs(ch.n_triangles - triangles) <= 0.1 * triangles
    assert trimesh.Trimesh(ch.pose(hand.rest_vertices), ch.faces, process=False).is_watertight
    # each vertex is a barycentric point of one of the full hand's closed triangles
    full_faces = {tuple(sorted(f)) for f in np.asarray(hand.closed_faces).tolist()}
    assert all(tuple(sorted(ids)) in full_faces for ids in ch.vertex_ids.tolist())
    assert ch.weights.min() >= 0 and np.allclose(ch.weights.sum(1), 1.0, atol=1e-12)
    full = hand.vertices(_random_grasps(hand, 3, seed=triangles))  # (3, V, 3), m
    posed = ch.pose(full)
    assert posed.shape == (3, len(ch.vertex_ids), 3)
    np.testing.assert_array_equal(ch.pose(full[1]), posed[1])  # one hand or a batch: the same numbers
    for v, c in zip(full, posed):
        # exact distances to the full posed surface, in mm (trimesh's tolerances are absolute)
        surface = trimesh.Trimesh(v * 1e3, hand.closed_faces, process=False)
        _, d_mm, _ = trimesh.proximity.closest_point(surface, c * 1e3)
        assert d_mm.max() * 1e-3 < 1e-6, d_mm.max()
        assert np.abs(c - v.mean(0)).max() < 0.3  # posed where the hand is


def test_a_count_outside_the_hands_range_is_refused(hand):
    with pytest.raises(ValueError, match="triangles"):
        build_collision_hand(hand.rest_vertices, hand.closed_faces, len(hand.closed_faces))
    with pytest.raises(ValueError, match="triangles"):
        build_collision_hand(hand.rest_vertices, hand.closed_faces, MIN_TRIANGLES - 1)


def test_the_cache_round_trips_and_a_damaged_entry_is_rebuilt_with_a_warning(hand, tmp_path, monkeypatch, caplog):
    built = collision_hand(hand, 800, tmp_path)
    (entry,) = (tmp_path / "sd_hand").glob("*.npz")
    assert not list((tmp_path / "sd_hand").glob(".*.tmp"))  # written atomically, nothing left beside it
    with np.load(entry, allow_pickle=False) as z:
        assert sorted(z.files) == ["faces", "vertex_ids", "weights"]

    def no_build(*args):
        raise AssertionError("rebuilt although the cache entry is good")

    monkeypatch.setattr("tohgs.hand.collision.build_collision_hand", no_build)
    again = collision_hand(hand, 800, tmp_path)
    for a, b in ((built.faces, again.faces), (built.vertex_ids, again.vertex_ids), (built.weights, again.weights)):
        np.testing.assert_array_equal(a, b)
    assert collision_hand(hand, 800, tmp_path).faces.dtype == np.int64
    monkeypatch.undo()

    good = entry.read_bytes()

    def write(**arrays):
        with open(entry, "wb") as fh:
            np.savez(fh, **{"faces": built.faces, "vertex_ids": built.vertex_ids, "weights": built.weights, **arrays})

    nan = built.weights.copy()
    nan[3, 0] = np.nan
    damaged = {
        "truncated": lambda: entry.write_bytes(good[: len(good) // 2]),
        "weights": lambda: write(weights=built.weights * 1.01),
        "ids": lambda: write(vertex_ids=built.vertex_ids + len(hand.rest_vertices)),
        "faces": lambda: write(faces=built.faces[:, :2]),
        "nan": lambda: write(weights=nan),
        "pickled": lambda: write(faces=built.faces.astype(object)),
    }
    for name, damage in damaged.items():
        damage()
        with pytest.raises(ValueError, match=entry.name):
            CollisionHand.load(entry, len(hand.rest_vertices))
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="tohgs.cache"):
            rebuilt = collision_hand(hand, 800, tmp_path)
        assert any("ignoring cache entry" in r.getMessage() and entry.name in r.getMessage()
                   for r in caplog.records), name
        np.testing.assert_array_equal(rebuilt.weights, built.weights)
        reread = CollisionHand.load(entry, len(hand.rest_vertices))  # replaced by a good entry
        np.testing.assert_array_equal(reread.vertex_ids, built.vertex_ids)
    other = collision_hand(hand, 1000, tmp_path)  # another count: another entry
    assert other.n_triangles == 1000 and len(list((tmp_path / "sd_hand").glob("*.npz"))) == 2


def test_the_setting_is_the_official_resolution_by_default_and_validates(default_config, hand):
    assert validate_config({})["evaluation"]["sd_hand"] == 1538  # MANO's triangles, as the official evaluation
    assert load_schema()["properties"]["evaluation"]["properties"]["sd_hand"]["minimum"] == MIN_TRIANGLES
    for good in ("full", 1600, MIN_TRIANGLES):
        assert validate_config({"evaluation": {"sd_hand": good}})["evaluation"]["sd_hand"] == good
    for bad, problem in (("fine", "does not match"), (MIN_TRIANGLES - 1, "out of range"), (1600.5, "expected"),
                         (True, "expected"), ("1600", "does not match")):
        cfg = copy.deepcopy(default_config)
        merge(cfg, {"evaluation": {"sd_hand": bad}})
        with pytest.raises(ConfigError) as exc:
            validate_config(cfg)
        assert "'evaluation.sd_hand'" in str(exc.value) and problem in str(exc.value), str(exc.value)
    assert sd_hand_of(hand, "full") is None
    assert sd_hand_of(hand, len(hand.closed_faces)) is None  # nothing to decimate: the full hand
    assert sd_hand_of(hand, 800.0).n_triangles == 800  # an integral float passes the schema
    for bad in ("fine", 100, 800.5, True):
        with pytest.raises(ValueError, match="evaluation.sd_hand"):
            sd_hand_of(hand, bad)


@pytest.fixture(scope="module")
def u_brick(tmp_path_factory):
    """The objects stage's U brick (its CoACD parts in ``collision.obj``), its mesh and vertex mean (as
    tests/test_sd_batch.py makes it)."""
    out = tmp_path_factory.mktemp("objects") / "brick-u-shape"
    prepare_small_object(ObjectSpec("brick-u-shape", "bricks", "stacking", None, "u-shape"), out, None)
    mesh = trimesh.load(out / "mesh.obj", force="mesh", process=False)
    return out / "collision.obj", mesh, np.asarray(mesh.vertices).mean(0)


def test_sd_with_the_collision_hand_is_within_a_few_mm_of_the_full_hands_on_held_grasps(hand, collision_1600,
                                                                                         u_brick):
    """Relaxed hands closed around the U brick (fingertips' and palm's centre at the brick's centre, turned
    at random: they hold it, as in tests/test_sd_batch.py): SD with the 1,600-triangle hand within 5 mm of
    the full hand's, both under QR's 2 cm. PV keeps the full mesh; SD, robust SD's batch and palm SD take
    the collision hand's vertices and faces."""
    path, mesh, centre = u_brick
    relaxed = hand.vertices(hand.presets["relaxed"][None])[0]
    grip = np.concatenate([relaxed[hand.tip_ids], relaxed[hand.palm_ids]]).mean(0)
    rng = np.random.default_rng(0)
    world = Rotation.from_quat(POSE[3:])
    verts = np.stack([world.apply(Rotation.random(random_state=rng).apply(relaxed - grip) + centre
                                  + rng.uniform(-0.01, 0.01, 3)) + POSE[:3] for _ in range(2)])
    faces, palm = np.asarray(hand.closed_faces), hand.palm_ids
    settings = SDSettings(gravity_direction="fixed", gravity=PAPER_GRAVITY)
    g = np.asarray(PAPER_GRAVITY)
    small = collision_1600.pose(verts)
    with DisplacementSimulator(path, centre, settings) as sim:
        full = np.array([sim.displacement(v, faces, POSE, g) for v in verts])
        decimated = np.array([sim.displacement(v, collision_1600.faces, POSE, g) for v in small])
        assert (full < 0.02).all() and (decimated < 0.02).all(), (full, decimated)
        np.testing.assert_allclose(decimated, full, atol=0.005)

        voxels = surface_voxels(mesh)
        q_full = hand_quality(verts, faces, palm, mesh, voxels, sim, object_pose=POSE)
        q = hand_quality(verts, faces, palm, mesh, voxels, sim, object_pose=POSE,
                         sd_mesh=(small, collision_1600.faces))
        np.testing.assert_array_equal(q["pv"], q_full["pv"])
        np.testing.assert_array_equal(q["contact_distance"], q_full["contact_distance"])
        np.testing.assert_array_equal(q["sd"], decimated)
        with pytest.raises(ValueError, match="same 2 hands"):
            hand_quality(verts, faces, palm, mesh, voxels, sim, object_pose=POSE, sd_mesh=(small[:1], faces))

        far = SceneCollider([trimesh.creation.box((0.1, 0.1, 0.1),
                                                  transform=trimesh.transformations.translation_matrix([5, 5, 5]))])
        obj = _ObjectAssets(mesh, voxels, path, centre)
        rows = grasp_metrics(verts, verts, faces, palm, obj, POSE, far, 0.001, sim, palm_sd=True,
                             sd_hand=collision_1600)
        np.testing.assert_array_equal(rows["sd"], decimated)
        np.testing.assert_array_equal(rows["pv"], q_full["pv"])
        world_centre = world.apply(centre) + POSE[:3]
        up = palm_gravity(verts[:, palm].mean(1), world_centre, 9.8)
        np.testing.assert_array_equal(rows["sd_palm"], [sim.displacement(v, collision_1600.faces, POSE, u)
                                                         for v, u in zip(small, up)])
