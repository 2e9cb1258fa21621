"""FLEX for hands: its pose prior learns the training finger poses, and its optimisation takes hands that
start inside an obstacle out of the scene at both poses."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from helpers import pose_prior, prepared_component, train_steps
from tohgs.geometry.maps import sample_surface
from tohgs.grasps.flex import FlexProblem, FlexSettings, contact_groups, optimise, start_grasps
from tohgs.hand import load_hand


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def _t(a) -> torch.Tensor:
    return torch.as_tensor(a, dtype=torch.float32)


def _scene() -> tuple[torch.Tensor, ...]:
    """A 5 x 5 x 8 cm box on a table, a wall 5 cm from its +x face (room for a hand), and the goal 30 cm along +x with a
    wall at the same place relative to it: a hand on the box's +x side is in a wall at both poses."""
    box = trimesh.creation.box((0.05, 0.05, 0.08))
    p, n = sample_surface(box, 512, np.random.default_rng(0))
    parts = [trimesh.creation.box((0.8, 0.4, 0.02)), trimesh.creation.box((0.02, 0.3, 0.3)),
             trimesh.creation.box((0.02, 0.3, 0.3))]
    for part, at in zip(parts, [(0.15, 0, -0.05), (0.085, 0, 0.1), (0.385, 0, 0.1)]):
        part.apply_translation(at)
    sp, sn = sample_surface(trimesh.util.concatenate(parts), 3000, np.random.default_rng(1))
    goal = torch.eye(4)
    goal[0, 3] = 0.3
    return _t(p), _t(n), _t(sp), _t(sn), goal


def test_flex_takes_hands_that_start_inside_an_obstacle_out_of_the_scene_at_both_poses(hand):
    points, normals, scene, scene_normals, goal = _scene()
    settings = FlexSettings(steps=120, drop_at=(), search_every=5, init_distance=(0.02, 0.03))
    # starts on the +x side of the box (palm towards it): their backs are in the wall, at both poses
    cands = start_grasps(hand, points, 256, settings, torch.Generator().manual_seed(0))
    with torch.no_grad():
        palm = hand(cands).vertices[:, hand.assets.palm_ids].mean(1)
    side = palm[:, 0] / palm.norm(dim=-1) > 0.85
    start = cands[side][:8]
    problem = FlexProblem(hand, points, normals, scene, scene_normals, goal, settings)
    prior = pose_prior(hand)
    with torch.no_grad():
        start[:, 6:] = prior.decode(torch.zeros(len(start), prior.cfg.latent))
    init0, goal0 = problem.opp(start)
    assert len(start) == 8 and float(init0.mean()) > 0.05 and float(goal0.mean()) > 0.05, (init0, goal0)
    grasp, history = optimise(hand, prior, points, normals, scene, scene_normals, goal, 8, settings,
                              torch.Generator().manual_seed(0), start=start)
    init1, goal1 = problem.opp(grasp)
    assert float(init1.mean()) < 0.25 * float(init0.mean()) and float(goal1.mean()) < 0.25 * float(goal0.mean()), (
        init0.mean(), init1.mean(), goal0.mean(), goal1.mean())
    assert history["obstacle"][-1] < 0.25 * history["obstacle"][0]
    # the hands stay at the object: most hands' nearest contact candidate within 1 cm of it
    with torch.no_grad():
        cand = hand(grasp).vertices[:, hand.contact_ids]
    near = torch.cdist(cand, points[None]).amin((1, 2))
    assert float(near.median()) < 0.01, near
    lim = hand.joint_limits.reshape(45, 2)
    assert ((grasp[:, 6:] >= lim[:, 0] - 1e-6) & (grasp[:, 6:] <= lim[:, 1] + 1e-6)).all()


def test_drops_keep_the_best_candidates_and_too_few_survivors_are_refused(hand):
    points, normals, scene, scene_normals, goal = _scene()
    settings = FlexSettings(steps=30, batch=16, drop_at=(10, 20))
    assert settings.survivors() == 4
    grasp, history = optimise(hand, pose_prior(hand), points, normals, scene, scene_normals, goal, 4, settings,
                              torch.Generator().manual_seed(1))
    assert grasp.shape == (4, 51) and torch.isfinite(grasp).all() and len(history["energy"]) == 31
    with pytest.raises(ValueError, match="raise flex.batch"):
        optimise(hand, pose_prior(hand), points, normals, scene, scene_normals, goal, 5, settings, torch.Generator())
    with pytest.raises(ValueError, match="drop_at"):
        FlexSettings(drop_at=(100, 50))
    groups = contact_groups(hand)
    assert groups.shape == hand.contact_ids.shape and set(groups.tolist()) == set(range(6))


def test_a_trained_pose_prior_reconstructs_the_training_poses_better_than_an_untrained_one(built):  # noqa: F811
    tmp, hand, _, _, _ = built
    net = {"latent": 8, "hidden": [64, 64]}
    fresh, data = prepared_component("pose_prior", net, tmp / "shard-0.zarr", hand)
    trained, _ = prepared_component("pose_prior", net, tmp / "shard-0.zarr", hand)
    train_steps(trained, data, 200)
    fingers = torch.as_tensor(np.concatenate([np.asarray(s.grasp) for s in data.shards]))[:, 6:]

    def error(model):
        with torch.no_grad():
            return float((model.decode(model.encode(fingers)[0]) - fingers).abs().mean())

    assert error(trained) < 0.5 * error(fresh), (error(trained), error(fresh))
    # the prior's mean latent decodes near the training poses' mean
    with torch.no_grad():
        mean_pose = trained.decode(torch.zeros(1, 8))[0]
    assert float((mean_pose - fingers.mean(0)).abs().mean()) < 0.1
