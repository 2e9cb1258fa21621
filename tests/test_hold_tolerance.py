"""benchmarks/hold_tolerance.py's perturbation: one error per grasp, the same in the hand's frame at both poses."""

import numpy as np
from scipy.spatial.transform import Rotation

from helpers import load_benchmark
from tohgs.geometry.grasp import transform_grasp
from tohgs.hand import load_hand_assets

hold_tolerance = load_benchmark("hold_tolerance")


def test_a_perturbed_goal_hand_is_the_perturbed_initial_hand_carried_with_the_object():
    hand = load_hand_assets("anny")
    rng = np.random.default_rng(0)
    init = np.concatenate([rng.normal(0, 0.05, (8, 3)), rng.normal(0, 1.0, (8, 3)), rng.normal(0, 0.2, (8, 45))], 1)
    move = np.eye(4)
    move[:3, :3] = Rotation.from_rotvec([0.3, -1.2, 0.7]).as_matrix()
    move[:3, 3] = [0.4, -0.1, 0.25]
    goal = transform_grasp(init, move, hand.rest_joints[0])
    new_init, new_goal = hold_tolerance.perturb(init, goal, 1.0, np.random.default_rng(1))
    carried = hand.vertices(new_init) @ move[:3, :3].T + move[:3, 3]
    np.testing.assert_allclose(hand.vertices(new_goal), carried, atol=1e-9)
    # A real error: the hands moved by about the scale's centimetres, and scale 0 moves nothing.
    moved = hold_tolerance.vertex_distance(hand, new_init, init)
    assert 0.005 < np.median(moved) < 0.05
    same_init, same_goal = hold_tolerance.perturb(init, goal, 0.0, np.random.default_rng(1))
    assert np.abs(hand.vertices(same_init) - hand.vertices(init)).max() < 1e-9
    # The wrong composition (the error in the world frame, dR R) would not carry: the test can fail.
    d_rot = Rotation.from_rotvec([0.2, 0.0, 0.0]).as_matrix()
    wrong = init.copy()
    wrong[:, 3:6] = Rotation.from_matrix(d_rot @ Rotation.from_rotvec(init[:, 3:6]).as_matrix()).as_rotvec()
    wrong_goal = goal.copy()
    wrong_goal[:, 3:6] = Rotation.from_matrix(d_rot @ Rotation.from_rotvec(goal[:, 3:6]).as_matrix()).as_rotvec()
    carried_wrong = hand.vertices(wrong) @ move[:3, :3].T + move[:3, 3]
    assert np.abs(hand.vertices(wrong_goal) - carried_wrong).max() > 1e-3
