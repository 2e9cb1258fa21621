"""GraspTTA and its variants: the cloud inside test, ICP, the test-time adaptation, GraspCVAE and ContactNet
learning, and the method's predictions with F-GraspTTA's filter."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from helpers import prepared_component, train_steps
from tohgs.data.batch import Batch
from tohgs.geometry.cloud import cloud_signed_distance, penetration_fraction
from tohgs.geometry.maps import sample_surface, scene_cloud
from tohgs.geometry.registration import ICPSettings, register, transform_error
from tohgs.grasps.tta import TTASettings, adapt, clamp_to_limits, tta_energy
from tohgs.methods.filtered import estimate_goal_transform, scene_views
from tohgs.models.component import build_component


def _box_scene(rng):
    """A table top (1 x 1 x 0.05 m, top face at z = 0) and a 10 cm cube obstacle standing on it."""
    table = trimesh.creation.box(extents=[1.0, 1.0, 0.05])
    table.apply_translation([0, 0, -0.025])
    cube = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    cube.apply_translation([0.2, 0.0, 0.05])
    return scene_cloud([table, cube], 3000, rng)


def test_the_scene_cloud_tells_inside_from_outside():
    cloud, normals = _box_scene(np.random.default_rng(0))
    q = torch.tensor([[[0.0, 0.0, 0.01], [0.0, 0.0, -0.01], [0.2, 0.0, 0.05], [0.2, 0.0, 0.12], [0.0, 0.0, -0.06]]])
    d = cloud_signed_distance(q, torch.as_tensor(cloud[None], dtype=torch.float32),
                              torch.as_tensor(normals[None], dtype=torch.float32))[0]
    assert d[0] > 0.005 and d[3] > 0.01, "above the table and above the cube: outside"
    assert d[1] < -0.005 and d[2] < -0.02, "inside the table top and inside the cube"
    assert d[4] > 0, "below the table: outside"
    frac = penetration_fraction(q, torch.as_tensor(cloud[None], dtype=torch.float32),
                                torch.as_tensor(normals[None], dtype=torch.float32))
    assert frac.item() == pytest.approx(2 / 5)


def test_icp_recovers_a_known_transform_between_two_scene_clouds():
    rng = np.random.default_rng(1)
    obj = trimesh.creation.cylinder(radius=0.03, height=0.12)  # not symmetric under the cube's turns
    obj.apply_translation([0.0, 0.0, 0.02])
    obj = trimesh.util.concatenate([obj, trimesh.creation.box(extents=[0.02, 0.08, 0.02])])
    points, _ = sample_surface(obj, 512, rng)
    points -= points.mean(0)
    scene, _ = _box_scene(rng)
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("zyx", [70, 20, -35], degrees=True).as_matrix()
    truth[:3, 3] = [-0.25, 0.3, 0.1]
    init_scene, goal_scene = scene_views(points + [0, 0, 0.3], _shift(truth, [0, 0, 0.3]), scene, seed=3)
    estimate, moved = estimate_goal_transform(points + [0, 0, 0.3], init_scene, goal_scene, ICPSettings(), 0.005)
    err = transform_error(estimate, _shift(truth, [0, 0, 0.3]), points + [0, 0, 0.3])
    assert moved == 256, "exactly the target's goal half moved"
    assert err["rotation_deg"] < 3 and err["translation_m"] < 0.005 and err["point_m"] < 0.005, err
    turned = register(points, points @ truth[:3, :3].T, ICPSettings())  # a pure turn of 70 degrees and more
    assert transform_error(turned.transform, _rot(truth), points)["rotation_deg"] < 1.0


def _shift(T, d):
    """``T`` expressed for points offset by ``d``: ``S T S^-1``."""
    S = np.eye(4)
    S[:3, 3] = d
    return S @ T @ np.linalg.inv(S)


def _rot(T):
    out = np.eye(4)
    out[:3, :3] = T[:3, :3]
    return out


@pytest.fixture(scope="module")
def hand():
    from tohgs.hand import load_hand

    return load_hand("anny")


def _sphere(n=400, r=0.035):
    pts, _ = sample_surface(trimesh.creation.icosphere(3, r), n, np.random.default_rng(0))
    return torch.as_tensor(pts, dtype=torch.float32)


def test_the_adaptation_lowers_its_energy_and_keeps_the_joints_in_their_limits(hand):
    torch.manual_seed(0)
    net = build_component("contact_net", {"object_mlp": [16], "hand_mlp": [16], "head": [16]}).eval()
    pts = _sphere()
    g = hand.preset("relaxed", 4).clone()
    with torch.no_grad():
        palm = hand(g).vertices[:, hand.assets.palm_ids].mean(1)
    g[:, :3] += -palm + torch.tensor([[0.0, 0.0, 0.01], [0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.02]])  # into the ball
    lim = hand.joint_limits.reshape(45, 2)
    g[:, 6:] = lim[:, 1] + 0.3  # every finger number beyond its limit
    s = TTASettings(steps=150)
    out, history = adapt(hand, g, pts.expand(4, -1, -1), net, 100.0, s)
    assert history["energy"][-1] < 0.5 * history["energy"][0], history["energy"][::30]
    assert history["penetration"][-1] < 0.5 * history["penetration"][0]
    assert (out[:, 6:] >= lim[:, 0] - 1e-6).all() and (out[:, 6:] <= lim[:, 1] + 1e-6).all()
    e = tta_energy(hand, out, pts.expand(4, -1, -1), net, 100.0, s)["energy"]
    np.testing.assert_allclose(e.mean().item(), history["energy"][-1], rtol=1e-5)
    same, _ = adapt(hand, g, pts.expand(4, -1, -1), net, 100.0, TTASettings(steps=0))
    torch.testing.assert_close(same, clamp_to_limits(g, hand.joint_limits))
    # Kept correspondences (search_every > 1, an option; the default searches every step) also lower the
    # energy: here the exact search ends at 3.7, oscillating between nearest vertices, the kept ones at 0.07
    # (on real data the end energies are within 16 % of each other, docs/baselines.md)
    _, h_kept = adapt(hand, g, pts.expand(4, -1, -1), net, 100.0, TTASettings(steps=150, search_every=5))
    assert s.search_every == 1 and h_kept["energy"][-1] < 0.5 * h_kept["energy"][0]
    assert h_kept["energy"][-1] < 1.25 * history["energy"][-1], (h_kept["energy"][-1], history["energy"][-1])
    with pytest.raises(ValueError, match="search_every"):
        TTASettings(search_every=0)
    # the record of touching hands: all four start in the ball; a hand 10 cm away touches nothing
    assert history["touching"][0] == 1.0 and 0.0 <= history["touching"][-1] <= 1.0
    away = g.clone()
    away[:, 0] += 0.1
    assert tta_energy(hand, away, pts.expand(4, -1, -1), net, 100.0, s)["touching"].tolist() == [0.0] * 4


CVAE = {"object_mlp": [32, 64], "hand_mlp": [32, 64], "encoder": [64], "decoder": [64], "latent": 8}


@pytest.mark.parametrize("contact_channel", [False, True])
def test_a_trained_grasp_cvae_reconstructs_its_training_grasps_better_than_an_untrained_one(built, contact_channel):  # noqa: F811
    tmp, hand, _, _, _ = built
    net = {**CVAE, "contact_channel": contact_channel}
    fresh, data = prepared_component("grasp_cvae", net, tmp / "shard-0.zarr", hand)
    trained, _ = prepared_component("grasp_cvae", net, tmp / "shard-0.zarr", hand)
    train_steps(trained, data, 150)
    batch = Batch.collate([data.item(i, 0) for i in range(len(data))])

    def vertex_error(model):
        with torch.no_grad():
            return (hand(model.reconstruct(batch, hand)).vertices - hand(batch.grasp).vertices).norm(dim=-1).mean().item()

    e_fresh, e_trained = vertex_error(fresh.eval()), vertex_error(trained)
    assert e_trained < 0.5 * e_fresh, (e_trained, e_fresh)
    samples = trained.sample_grasps(batch, "ddim", 1, torch.Generator().manual_seed(0))
    assert samples.shape == batch.grasp.shape and torch.isfinite(samples).all()
    if contact_channel:
        with pytest.raises(ValueError, match="contact map"):
            trained.sample_grasps(Batch(**{**batch.__dict__, "contact": None}), "ddim", 1, torch.Generator())


def test_a_trained_contact_net_predicts_the_true_map_of_a_perturbed_hand_better_than_an_untrained_one(built):  # noqa: F811
    from tohgs.models.contact_net import perturb_grasps

    tmp, hand, _, _, _ = built
    net = {"object_mlp": [32], "hand_mlp": [32], "head": [32]}
    fresh, data = prepared_component("contact_net", net, tmp / "shard-0.zarr", hand)
    trained, _ = prepared_component("contact_net", net, tmp / "shard-0.zarr", hand)
    train_steps(trained, data, 150)
    batch = Batch.collate([data.item(i, 1) for i in range(len(data))])
    with torch.no_grad():
        verts = hand(perturb_grasps(batch.grasp, trained.cfg.noise, torch.Generator().manual_seed(5))).vertices
        err = {k: ((m.eval().predict_map(batch.points, verts) - batch.contact) ** 2).mean().item()
               for k, m in (("fresh", fresh), ("trained", trained))}
    assert err["trained"] < 0.5 * err["fresh"], err


GRASPTTA = {"label": "GraspTTA", "kind": "grasp_tta", "cvae": "grasp_cvae", "contact_net": "contact_net", "contact": "none"}


@pytest.fixture(scope="module")
def tta_models(built, tmp_path_factory):  # noqa: F811
    from tohgs.models.train import train_component

    tmp, hand, _, _, _ = built
    out = tmp_path_factory.mktemp("tta")
    settings = {"steps": 20, "batch": 4, "warmup": 2, "log_every": 5, "checkpoint_every": 10, "train_points": 128,
                "device": "cpu"}
    paths = {}
    for name, kind, net in (("grasp_cvae", "grasp_cvae", CVAE), ("m_grasp_cvae", "grasp_cvae", {**CVAE, "contact_channel": True}),
                            ("contact_net", "contact_net", {"object_mlp": [16], "hand_mlp": [16], "head": [16]})):
        paths[name] = out / f"{name}.pt"
        train_component(name, kind, "placing", [tmp / "shard-0.zarr"], net, settings, paths[name], hand=hand)
    return tmp, out, paths


def test_grasptta_predicts_adapted_grasps_and_f_grasptta_filters_them(tta_models):
    from tohgs.data.predictions import read_predictions
    from tohgs.methods.predict import predict

    tmp, out, paths = tta_models
    hand_file = out / "hand.npz"
    from tohgs.hand import load_hand

    load_hand("anny").assets.save(hand_file)
    models = {k: paths[k] for k in ("grasp_cvae", "contact_net")}
    settings = {"samples": 4, "seed": 0, "device": "cpu", "tta": {"steps": 10}}
    a = predict("placing", "grasptta", GRASPTTA, [tmp / "shard-0.zarr"], models, settings, out / "a.zarr", hand=hand_file)
    again = predict("placing", "grasptta", GRASPTTA, [tmp / "shard-0.zarr"], models, {**settings, "chunk": 1},
                    out / "b.zarr", hand=hand_file)  # one configuration at a time: the same grasps as a chunk
    np.testing.assert_array_equal(a["grasp_init"], again["grasp_init"])
    np.testing.assert_array_equal(a["contact"], again["contact"])
    arrays, attrs = read_predictions(out / "a.zarr")
    assert arrays["kept"].all() and attrs["discarded"] == 0
    assert attrs["timing"]["seconds_per_adaptation"] > 0
    assert len(attrs["diagnostics"]["energy_end"]) == 2 and np.isfinite(attrs["diagnostics"]["energy_end"]).all()
    f_cfg = {"label": "F-GraspTTA", "kind": "filtered", "of": "grasptta"}
    f_settings = {"seed": 0, "device": "cpu", "filter": {"max_opp": 0.0}}  # a hand touching the table is dropped
    f = predict("placing", "f-grasptta", f_cfg, [tmp / "shard-0.zarr"], {}, f_settings, out / "f.zarr", hand=hand_file,
                base=out / "a.zarr")
    np.testing.assert_allclose(f["grasp_init"], a["grasp_init"], atol=1e-6)  # the same grasps, some discarded
    np.testing.assert_allclose(f["grasp_goal"], a["grasp_goal"], atol=1e-6)
    f_arrays, f_attrs = read_predictions(out / "f.zarr")
    diag = f_attrs["diagnostics"]
    assert len(diag["icp_rotation_deg"]) == 2 and np.isfinite(diag["icp_point_m"]).all()
    assert f_attrs["discarded"] == int((~f_arrays["kept"]).sum())
    assert diag["kept"] == f_arrays["kept"].sum(1).tolist()
    loose = predict("placing", "f-grasptta", f_cfg, [tmp / "shard-0.zarr"], {}, {**f_settings, "filter": {"max_opp": 1.0}},
                    out / "g.zarr", hand=hand_file, base=out / "a.zarr")
    assert loose["kept"].all(), "a threshold of 1 keeps every grasp"
    m = {**GRASPTTA, "cvae": "m_grasp_cvae", "contact": "ground_truth"}
    g = predict("placing", "m-grasptta-gt", m, [tmp / "shard-0.zarr"], {**models, "m_grasp_cvae": paths["m_grasp_cvae"]},
                settings, out / "m.zarr", hand=hand_file)
    from tohgs.data.maps import read_map_shard

    from tohgs.methods.base import ground_truth_pick

    sh = read_map_shard(tmp / "shard-0.zarr")
    pick = ground_truth_pick(sh, 0, g["contact"].shape[1], settings.get("seed", 0))  # the Dataset row's grasps
    np.testing.assert_array_equal(g["contact"][0], sh.contact[pick])
