"""Task expansion: rigid grasp transforms, and keeping or dropping grasps by scene collisions."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from helpers import placing_scene
from tohgs.assets.bricks import make_brick
from tohgs.assets.manifest import record_object_files
from tohgs.assets.supports import make_table
from tohgs.geometry.grasp import pose_matrix, transform_grasp
from tohgs.grasps.expand import ExpansionSettings, expand_configurations
from tohgs.hand import load_hand


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def test_transform_grasp_moves_the_hand_mesh_rigidly(hand):
    rng = np.random.default_rng(0)
    grasp = hand.preset("relaxed", 4).numpy().astype(np.float64)
    grasp[:, :6] = rng.normal(scale=0.3, size=(4, 6))
    pose = np.concatenate([rng.normal(size=3), Rotation.random(random_state=1).as_quat()])
    T = pose_matrix(pose)
    moved = transform_grasp(grasp, T, hand.rest_joints[0].numpy())
    with torch.no_grad():
        before = hand(torch.as_tensor(grasp, dtype=torch.float32)).vertices.numpy()
        after = hand(torch.as_tensor(moved, dtype=torch.float32)).vertices.numpy()
    np.testing.assert_allclose(after, before @ T[:3, :3].T + T[:3, 3], atol=2e-5)
    np.testing.assert_array_equal(moved[:, 6:], grasp[:, 6:])


def test_expansion_keeps_a_clear_grasp_and_drops_one_in_an_obstacle_or_the_table(hand, tmp_path):
    cube = make_brick("cube")
    cube.apply_translation(-cube.center_mass)
    (tmp_path / "brick-cube").mkdir()
    cube.export(tmp_path / "brick-cube" / "mesh.obj")
    record_object_files(tmp_path / "brick-cube", {"name": "brick-cube"}, ["mesh.obj"])
    supports = {"table": make_table()}
    # A hand above the cube (object frame): its lowest vertex 1 cm above the cube's top; another the
    # same but 8 cm lower (through the table once the cube rests on it).
    grasp = hand.preset("relaxed", 2).numpy().astype(np.float64)
    with torch.no_grad():
        low = hand(torch.as_tensor(grasp, dtype=torch.float32)).vertices.numpy()[:, :, 2].min(1)
    top = cube.vertices[:, 2].max()
    grasp[0, 2] += top + 0.01 - low[0]
    grasp[1, 2] += top - 0.08 - low[1]
    out = expand_configurations(placing_scene(None), grasp, hand.assets, tmp_path, supports, ExpansionSettings(0.002))
    assert out["prior_index"].tolist() == [0] and out["kept_per_config"].tolist() == [1]
    # the scene's difficulty: the low hand is in the table at both poses
    assert out["rejected_init"].tolist() == [1] and out["rejected_goal"].tolist() == [1]
    # An obstacle right where the kept hand is at the initial pose (the hand spans ~10 cm around the
    # wrist): now nothing is kept.
    with torch.no_grad():
        v = hand(torch.as_tensor(grasp[:1], dtype=torch.float32)).vertices.numpy()[0]
    xy = v[:, :2].mean(0) + np.array([0.0, 0.0])
    centre = np.array([*xy, 0.03 + top + 0.01 + 0.03])
    blocked = placing_scene(None)
    blocked.obstacle_offsets = np.array([0, 1], np.int64)
    blocked.obstacle_id = np.zeros(1, np.int32)
    blocked.obstacle_pose = np.array([[*centre, 0, 0, 0, 1.0]])
    out = expand_configurations(blocked, grasp, hand.assets, tmp_path, supports, ExpansionSettings(0.002))
    assert out["kept_per_config"].tolist() == [0]
    # the obstacle stands where the cube was picked up, not where it goes: both hands rejected there only
    assert out["rejected_init"].tolist() == [2] and out["rejected_goal"].tolist() == [1]
    # World-frame grasps of the kept hand: at the goal, the hand moved with the cube by 0.3 m in x.
    out = expand_configurations(placing_scene(None), grasp, hand.assets, tmp_path, supports, ExpansionSettings(0.002))
    np.testing.assert_allclose(out["grasp_goal"][0, :3] - out["grasp_init"][0, :3], [0.3, 0, 0], atol=1e-6)
    # No accepted prior grasp: no task grasp, every configuration counted.
    none = expand_configurations(placing_scene(None), grasp[:0], hand.assets, tmp_path, supports, ExpansionSettings(0.002))
    assert none["grasp_init"].shape == (0, 51) and none["kept_per_config"].tolist() == [0]
    assert none["rejected_init"].tolist() == [0] and none["rejected_goal"].tolist() == [0]
