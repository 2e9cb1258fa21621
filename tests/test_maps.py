"""Maps: distances and normalisation against brute force, sampling, shards (round trip, refusals,
determinism) and the dataset's rotation augmentation."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import torch
import trimesh

from tohgs.assets.manifest import record_object_files
from tohgs.data.build_maps import make_map_shard, shard_items
from tohgs.data.maps import SCHEMA_VERSION, MapDataset, read_map_shard
from tohgs.geometry.maps import (ALPHA_CONTACT, ALPHA_DISTANCE, nearest_distance, nearest_distance_brute, normalised_map,
                                 sample_surface, scene_cloud)
from tohgs.geometry.sampling import farthest_point_sampling, farthest_point_sampling_reference


def test_nearest_distances_match_brute_force():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(700, 3)), rng.normal(size=(1300, 3))
    np.testing.assert_allclose(nearest_distance(a, b), nearest_distance_brute(a, b), rtol=1e-12)
    np.testing.assert_allclose(nearest_distance(b[:5], b), 0.0)


def test_the_two_alphas_have_one_home():
    """tohgs.geometry.maps' alphas are the library's defaults and the schema's. GuidanceSettings writes the
    contact alpha out (the workflow's parse imports it, without numpy): pinned here."""
    from tohgs.config import validate_config
    from tohgs.data.build_maps import MapSettings
    from tohgs.models.guidance_settings import GuidanceSettings

    cfg = validate_config({})
    assert (MapSettings().alpha_distance, MapSettings().alpha_contact) == (ALPHA_DISTANCE, ALPHA_CONTACT)
    assert (cfg["maps"]["points"]["alpha_distance"], cfg["maps"]["points"]["alpha_contact"]) == (ALPHA_DISTANCE, ALPHA_CONTACT)
    assert GuidanceSettings().alpha == cfg["prediction"]["steer"]["alpha"] == ALPHA_CONTACT


def test_normalised_map_is_one_at_contact_and_falls_with_distance():
    d = np.array([0.0, 0.01, 0.05, 0.2])
    m = normalised_map(d, 30.0)
    assert m[0] == pytest.approx(1.0) and np.all(np.diff(m) < 0) and np.all(m > 0)
    assert m[1] == pytest.approx(1 - 2 * (1 / (1 + np.exp(-0.3)) - 0.5))
    assert normalised_map(0.01, 100.0) < normalised_map(0.01, 30.0)  # contact maps are sharper


def test_surface_samples_lie_on_the_surface_with_outward_normals():
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.04])
    pts, nrm = sample_surface(box, 2000, np.random.default_rng(0))
    assert np.abs(np.abs(pts) - [0.05, 0.03, 0.02]).min(1).max() < 1e-9  # each point on some face
    assert ((pts * nrm).sum(1) > 0).all()
    # Area-weighted: the two large faces (0.1 x 0.06) hold about 0.006 / 0.0148 of the samples.
    share = (np.abs(nrm[:, 2]) > 0.5).mean()
    assert share == pytest.approx(2 * 0.1 * 0.06 / (2 * (0.1 * 0.06 + 0.1 * 0.04 + 0.06 * 0.04)), abs=0.04)


def test_farthest_point_sampling_covers_better_than_random():
    rng = np.random.default_rng(1)
    pts = rng.random((3000, 3))
    idx = farthest_point_sampling(pts, 100)
    assert len(np.unique(idx)) == 100
    cover_fps = nearest_distance(pts, pts[idx]).max()
    cover_rand = nearest_distance(pts, pts[rng.choice(3000, 100, replace=False)]).max()
    assert cover_fps < 0.75 * cover_rand
    cloud, normals = scene_cloud([trimesh.creation.box(extents=[1, 1, 0.05])], 256, np.random.default_rng(0))
    assert cloud.shape == (256, 3) and normals.shape == (256, 3)
    # each normal is the outward normal of the face its point lies on: a top point's is +z, a side's horizontal
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
    top = cloud[:, 2] > 0.0249
    assert top.any() and np.allclose(normals[top], [0, 0, 1], atol=1e-6)
    side = np.abs(cloud[:, 0]) > 0.4999
    assert side.any() and np.allclose(np.abs(normals[side, 0]), 1.0, atol=1e-6)


def test_farthest_point_sampling_matches_the_numpy_reference():
    pts = np.random.default_rng(2).normal(size=(2000, 3))
    for start in (0, 17):
        fast = farthest_point_sampling(pts, 300, start)
        ref = farthest_point_sampling_reference(pts, 300, start)
        assert len(np.unique(fast)) == 300 and start in fast
        assert set(fast.tolist()) == set(ref.tolist())  # the same points (open3d returns them in index order)


def test_shard_items_deal_configurations_round_robin():
    n = {"b": 3, "a": 2}
    all_items = shard_items(n, "train", 10, 1, 0)
    assert all_items == [("a", 0), ("a", 1), ("b", 0), ("b", 1), ("b", 2)]
    parts = [shard_items(n, "train", 10, 2, k) for k in range(2)]
    assert sorted(parts[0] + parts[1]) == all_items and len(parts[0]) == 3
    assert shard_items(n, "test", 1, 1, 0) == [("a", 0), ("b", 0)]
    with pytest.raises(ValueError, match="out of range"):
        shard_items(n, "train", 10, 2, 2)


def test_shard_contents_and_maps(built):
    tmp, hand, shard, _, cube = built
    assert shard.n_configs == 2 and shard.n_grasps == 6
    back = read_map_shard(tmp / "shard-0.zarr")
    for k in ("points", "d_init", "contact", "grasp", "goal_transform"):
        np.testing.assert_array_equal(back.arrays[k], shard.arrays[k])
    assert np.abs(shard.points.mean(1)).max() < 1e-6  # network frame: centred at the initial pose
    # The cube rests on the table at both poses: its bottom points are at the scene (D ~ 1), its top far.
    z = shard.points[0, :, 2]
    bottom, top = z < z.min() + 1e-4, z > z.max() - 1e-4
    assert shard.d_init[0][bottom].mean() > 0.8 and shard.d_init[0][top].max() < 0.5
    assert shard.d_goal[0][bottom].mean() > 0.8
    # The contact map lights up where the hand is: the top face, not the bottom one.
    c = shard.contact[0]
    assert c[top].max() > 0.6 and c[bottom].max() < 0.1
    # The hand rebuilt from the stored grasp (network frame) touches the points the map says it does.
    with torch.no_grad():
        hv = hand(torch.as_tensor(shard.grasp[:1])).vertices.numpy()[0]
    np.testing.assert_allclose(normalised_map(nearest_distance(shard.points[0], hv), 100.0), c, atol=1e-4)


def test_same_seed_same_shard_and_broken_shards_are_refused(built):
    tmp, _, shard, kw, _ = built
    again = make_map_shard(shard=0, out=tmp / "again.zarr", **kw)
    for k, v in shard.arrays.items():
        np.testing.assert_array_equal(again.arrays[k], v)
    bad = tmp / "bad.zarr"
    shutil.copytree(tmp / "shard-0.zarr", bad)
    shutil.rmtree(bad / "contact")
    with pytest.raises(ValueError, match=r"bad.zarr: missing array 'contact'"):
        read_map_shard(bad)
    shutil.rmtree(bad)
    shutil.copytree(tmp / "shard-0.zarr", bad)
    for f in (bad / "points" / "c").rglob("*"):
        if f.is_file():
            f.write_bytes(f.read_bytes()[: len(f.read_bytes()) // 2])  # truncated shard file
    with pytest.raises(ValueError, match=r"bad.zarr: array 'points' is unreadable or truncated"):
        read_map_shard(bad)
    meta = bad / "zarr.json"
    meta.write_text(meta.read_text().replace(f'"schema_version": {SCHEMA_VERSION}', '"schema_version": 99'))
    with pytest.raises(ValueError, match="bad.zarr: schema version 99"):
        read_map_shard(bad)


def test_the_so3_draw_is_uniform_and_the_z_draw_is_not():
    """Haar-uniform rotations: the image of any fixed axis is uniform on the sphere, so its z component is
    uniform on [-1, 1] (Archimedes) and E[R] = 0; an upright draw about z fails both."""
    from scipy import stats

    from tohgs.data.maps import random_rotation
    from tohgs.models.train import TrainSettings

    assert TrainSettings().rotation == "so3"  # the paper's protocol is the default
    rng = np.random.default_rng(0)
    so3 = np.stack([random_rotation(rng, "so3") for _ in range(4000)])
    for axis in range(3):
        cos = so3[:, 2, axis]  # the z component of the rotated axis
        assert stats.kstest(cos, stats.uniform(loc=-1, scale=2).cdf).pvalue > 1e-3, axis
    assert np.abs(so3.mean(0)).max() < 0.05
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", so3, so3), np.broadcast_to(np.eye(3), so3.shape), atol=1e-12)
    upright = np.stack([random_rotation(rng, "z") for _ in range(4000)])
    assert stats.kstest(upright[:, 2, 2], stats.uniform(loc=-1, scale=2).cdf).pvalue < 1e-6
    assert np.abs(upright.mean(0)).max() > 0.5  # R[2, 2] is always 1


def test_rotation_augmentation_rotates_the_hand_mesh(built):
    tmp, hand, _, _, _ = built
    plain = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    turned = MapDataset([tmp / "shard-0.zarr"], per="grasp", rotation="so3", seed=3)
    assert len(plain) == 6
    for i in range(len(plain)):
        a, b = plain[i], turned[i]
        # Recover R from the points (same order), then compare the hand meshes.
        R, *_ = np.linalg.lstsq(a["points"].astype(np.float64), b["points"].astype(np.float64), rcond=None)
        with torch.no_grad():
            va = hand(torch.as_tensor(a["grasp"][None])).vertices.numpy()[0]
            vb = hand(torch.as_tensor(b["grasp"][None])).vertices.numpy()[0]
        np.testing.assert_allclose(vb, va @ R, atol=1e-4)
        np.testing.assert_array_equal(a["contact"], b["contact"])
    assert not np.allclose(turned[0]["points"], turned[1]["points"])  # a new rotation per item
    tests = MapDataset([tmp / "shard-0.zarr"], per="config")
    assert len(tests) == 2 and "grasp" not in tests[0]



class _Store:
    """A scene-store stand-in: its ``object``, ``attrs`` and number of configurations."""

    def __init__(self, name: str, n: int, attrs: dict) -> None:
        self.object, self.attrs, self._n = name, attrs, n

    def __len__(self) -> int:
        return self._n


def test_an_official_test_store_offers_the_configurations_its_evaluation_uses():
    """An imported Shelving test store records the configurations the official evaluation uses (every tenth
    from the 51st): the test split takes the first ``test_configs`` of those; other stores offer all."""
    from tohgs.data.build_maps import evaluation_candidates

    shelving = _Store("off-a", 83, {"official": {"evaluated": list(range(50, 83, 10))}})
    n = {"off-a": evaluation_candidates(shelving), "b": evaluation_candidates(_Store("b", 5, {}))}
    assert n == {"off-a": [50, 60, 70, 80], "b": 5}
    assert shard_items(n, "test", 3, 1, 0) == [("b", 0), ("b", 1), ("b", 2),
                                              ("off-a", 50), ("off-a", 60), ("off-a", 70)]
    assert shard_items(n, "test", 3, 2, 1) == [("b", 1), ("off-a", 50), ("off-a", 70)]
    # a store too short for the official choice (none evaluated) offers all its configurations
    assert evaluation_candidates(_Store("off-c", 4, {"official": {"evaluated": []}})) == 4


def test_a_test_split_takes_configurations_with_ground_truth_only():
    from tohgs.data.build_maps import with_ground_truth

    kept = np.array([0, 2, 0, 1])
    assert with_ground_truth(4, kept) == [1, 3]
    assert with_ground_truth([3, 1, 0], kept) == [3, 1]  # an official store's order is kept
    assert shard_items({"a": with_ground_truth(4, kept), "b": 2}, "test", 1, 1, 0) == [("a", 1), ("b", 0)]


class _Obstacles:
    """A scene-set stand-in with one obstacle per configuration: what obstacle_gaps reads."""

    def __init__(self, init, goal, obstacle):
        self.target_init_pose, self.target_goal_pose, self._obstacle = np.asarray(init), np.asarray(goal), obstacle

    def obstacles(self, c):
        return [] if self._obstacle[c] is None else [("box", self._obstacle[c])]


def test_obstacle_gaps_are_the_distance_from_the_target_to_its_nearest_obstacle(tmp_path):
    """Two 4 cm cubes, faces parallel: 10 cm apart centre to centre at the initial pose (a 6 cm gap), 5 cm
    at the goal (1 cm); no obstacle gives NaN."""
    from tohgs.geometry.maps import sample_surface
    from tohgs.geometry.scene import obstacle_gaps

    cube = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    (tmp_path / "box").mkdir()
    cube.export(tmp_path / "box" / "mesh.obj")
    record_object_files(tmp_path / "box", {"name": "box"}, ["mesh.obj"])
    pts, _ = sample_surface(cube, 2000, np.random.default_rng(0))
    here, there = [0, 0, 0, 0, 0, 0, 1.0], [0.05, 0, 0, 0, 0, 0, 1.0]
    scenes = _Obstacles([here, here], [there, there], [[0.1, 0, 0, 0, 0, 0, 1.0], None])
    gi, gg = obstacle_gaps(scenes, 0, tmp_path, pts)
    assert gi == pytest.approx(0.06, abs=2e-4) and gg == pytest.approx(0.01, abs=2e-4)
    assert all(np.isnan(obstacle_gaps(scenes, 1, tmp_path, pts)))
