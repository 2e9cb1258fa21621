"""Training and prediction on a tiny shard: checkpoints, resuming, EMA weights, predictions' frames."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from helpers import OURS, SETTINGS, TINY
from tohgs.data.predictions import read_predictions
from tohgs.geometry.grasp import transform_grasp
from tohgs.methods.predict import predict
from tohgs.models.checkpoint import load_component
from tohgs.models.train import train_component

OURS_GT = {"label": "Ours (GT contact)", "kind": "contact_grasp", "contact": "ground_truth", "grasp": "grasp_diffuser"}


@pytest.fixture(scope="module")
def trained(built, tmp_path_factory):  # noqa: F811
    tmp, hand, _, _, _ = built
    out = tmp_path_factory.mktemp("models")
    paths = {}
    for name in ("contact_diffuser", "grasp_diffuser"):
        paths[name] = out / f"{name}.pt"
        train_component(name, name, "placing", [tmp / "shard-0.zarr"], TINY[name], SETTINGS, paths[name], hand=hand,
                        curve_png=out / f"{name}.png")
    return tmp, hand, out, paths


def test_checkpoints_hold_weights_config_normaliser_and_curve(trained):
    import tohgs

    _, hand, out, paths = trained
    for name, path in paths.items():
        model, ckpt = load_component(path)
        assert ckpt["format"] == "tohgs.checkpoint" and ckpt["tohgs_version"] == tohgs.__version__
        assert ckpt["component"] == name == ckpt["kind"] == model.kind and ckpt["network_config"] == TINY[name]
        assert ckpt["training_config"]["steps"] == SETTINGS["steps"] and len(ckpt["loss_curve"]) == 5
        assert all(np.isfinite(r["loss"]) for r in ckpt["loss_curve"]) and (out / f"{name}.png").stat().st_size > 5000
        assert not path.with_name(path.name + ".resume").exists()
    g, ckpt = load_component(paths["grasp_diffuser"])
    assert not torch.allclose(g.grasp_std, torch.ones(g.dim)), "the grasp normaliser is saved"
    torch.testing.assert_close(ckpt["normaliser"]["std"], g.grasp_std)
    assert load_component(paths["contact_diffuser"])[1]["normaliser"] is None
    assert torch.allclose(g.wrist, hand.rest_joints[0]) and g.palm.abs().sum() > 0, "the hand's wrist and palm are saved"
    with pytest.raises(ValueError, match="not a readable checkpoint"):
        load_component(out / "contact_diffuser.png")
    torch.save({"name": "contact_diffuser", "state_dict": {}}, out / "old.pt")
    with pytest.raises(ValueError, match=r"old\.pt: not a tohgs checkpoint .*older tohgs"):
        load_component(out / "old.pt")


def test_an_interrupted_run_resumes_to_the_same_weights(trained, monkeypatch):
    tmp, hand, out, paths = trained
    calls = {"n": 0}
    real = torch.nn.utils.clip_grad_norm_

    def crash(*a, **k):
        calls["n"] += 1
        if calls["n"] == 8:
            raise KeyboardInterrupt("simulated kill")
        return real(*a, **k)

    target = out / "again.pt"
    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", crash)
    with pytest.raises(KeyboardInterrupt):
        train_component("contact_diffuser", "contact_diffuser", "placing", [tmp / "shard-0.zarr"], TINY["contact_diffuser"],
                        SETTINGS, target,
                    hand=hand)
    assert target.with_name("again.pt.resume").is_file() and not target.exists()
    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", real)
    resumed = train_component("contact_diffuser", "contact_diffuser", "placing", [tmp / "shard-0.zarr"], TINY["contact_diffuser"],
                        SETTINGS,
                          target, hand=hand)
    straight = torch.load(paths["contact_diffuser"], weights_only=True)
    for k, v in straight["state_dict"].items():
        torch.testing.assert_close(resumed["state_dict"][k], v, msg=k)


def test_a_resume_file_of_an_older_format_is_refused_by_name(trained):
    tmp, hand, out, _ = trained
    target = out / "old.pt"
    torch.save({"model": {}, "ema": {"decay": 0.99, "optimization_step": 3, "shadow_params": []}},
               target.with_name("old.pt.resume"))
    with pytest.raises(ValueError, match=r"old\.pt\.resume.*older tohgs"):
        train_component("contact_diffuser", "contact_diffuser", "placing", [tmp / "shard-0.zarr"], TINY["contact_diffuser"],
                        SETTINGS, target,
                    hand=hand)


def test_predictions_are_reproducible_and_carried_to_the_goal(trained):
    tmp, hand, out, paths = trained
    settings = {"samples": 3, "sampler": "ddim", "steps": 4, "seed": 1, "device": "cpu"}
    a = predict("placing", "ours", OURS, [tmp / "shard-0.zarr"], paths, settings, out / "p.zarr")
    b = predict("placing", "ours", OURS, [tmp / "shard-0.zarr"], paths, settings, out / "q.zarr")
    np.testing.assert_array_equal(a["grasp_init"], b["grasp_init"])
    arrays, attrs = read_predictions(out / "p.zarr")
    assert arrays["grasp_init"].shape == (2, 3, 51) and arrays["contact"].shape == (2, 3, 256)
    assert attrs["timing"]["seconds_per_grasp"] > 0 and attrs["method_config"]["contact"] == "contact_diffuser"
    assert set(attrs["components"]) == {"contact_diffuser", "grasp_diffuser"}
    assert arrays["contact"].min() >= 0 and arrays["contact"].max() <= 1
    from tohgs.data.maps import read_map_shard

    sh = read_map_shard(tmp / "shard-0.zarr")
    wrist = np.asarray(sh.attrs["hand_wrist"])
    for c in range(2):
        moved = transform_grasp(arrays["grasp_init"][c], sh.goal_transform[c], wrist)
        np.testing.assert_allclose(arrays["grasp_goal"][c], moved, atol=1e-5)
    gt = predict("placing", "ours-gt-contact", OURS_GT, [tmp / "shard-0.zarr"], {"grasp_diffuser": paths["grasp_diffuser"]},
                 settings, out / "gt.zarr")
    np.testing.assert_array_equal(gt["contact"][0][0], sh.contact[np.flatnonzero(sh.grasp_config == 0)[0]])



def test_a_configurations_predictions_do_not_depend_on_the_configurations_before_it(trained, built):  # noqa: F811
    """Each configuration draws from its own streams (seed, object, configuration): configuration 1 predicted
    after configuration 0 equals configuration 1 predicted alone (a shard of its own), and the two
    configurations' samples differ."""
    from tohgs.data.build_maps import make_map_shard

    tmp, hand, out, paths = trained
    _, _, _, kw, _ = built
    both = make_map_shard(**{**kw, "split": "test", "n_shards": 1}, shard=0, out=out / "test-both.zarr")
    alone = make_map_shard(**{**kw, "split": "test", "n_shards": 2}, shard=1, out=out / "test-alone.zarr")
    assert list(both.config_index) == [0, 1] and list(alone.config_index) == [1]
    settings = {"samples": 3, "sampler": "ddim", "steps": 4, "seed": 1, "device": "cpu"}
    a = predict("placing", "ours", OURS, [out / "test-both.zarr"], paths, settings, out / "both.zarr")
    b = predict("placing", "ours", OURS, [out / "test-alone.zarr"], paths, settings, out / "alone.zarr")
    np.testing.assert_array_equal(b["config_index"], [1])
    np.testing.assert_array_equal(a["grasp_init"][1], b["grasp_init"][0])
    np.testing.assert_array_equal(a["contact"][1], b["contact"][0])
    assert np.abs(a["grasp_init"][0] - a["grasp_init"][1]).max() > 1e-3
    other = predict("placing", "ours", OURS, [out / "test-alone.zarr"], paths, {**settings, "seed": 2}, out / "seed2.zarr")
    assert np.abs(other["grasp_init"][0] - b["grasp_init"][0]).max() > 1e-3, "the seed changes the draw"
