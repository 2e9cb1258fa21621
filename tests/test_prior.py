"""The prior-grasp stage: store round trip and refusals, synthesis + metrics on one brick, the filter step."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from tohgs.assets.bricks import make_brick
from tohgs.assets.manifest import record_object_files
from tohgs.data.grasps import ENERGY_TERMS, PriorGrasps, read_prior_grasps, write_prior_grasps
from tohgs.grasps.prior import filter_prior_grasps, make_prior_grasps, object_seed, summarize_prior_grasps
from tohgs.hand import load_hand


def _grasps(b: int = 5, seed: int = 0) -> PriorGrasps:
    rng = np.random.default_rng(seed)
    return PriorGrasps(object="brick-cube", pose=rng.normal(size=(b, 51)).astype(np.float32),
                       contact_idx=rng.integers(0, 84, (b, 4)), plane=np.zeros((b, 4), np.float32),
                       energies={k: rng.random(b).astype(np.float32) for k in ENERGY_TERMS},
                       pv=rng.random(b) * 1e-5, sd=rng.random(b) * 0.05, contact_distance=rng.random(b) * 0.01,
                       attrs={"hand": "anny", "seed": seed})


def test_store_round_trip(tmp_path):
    g = _grasps()
    write_prior_grasps(g, tmp_path / "g.zarr")
    back = read_prior_grasps(tmp_path / "g.zarr", filtered=False)
    assert back.object == "brick-cube" and back.attrs["hand"] == "anny" and back.flags is None
    np.testing.assert_array_equal(back.pose, g.pose)
    np.testing.assert_array_equal(back.sd, g.sd)
    np.testing.assert_array_equal(back.energies["fc"], g.energies["fc"])
    with pytest.raises(ValueError, match="expected a filtered store"):
        read_prior_grasps(tmp_path / "g.zarr", filtered=True)


def test_broken_stores_are_refused_by_name(tmp_path):
    with pytest.raises(ValueError, match="missing.zarr: prior-grasp store not found"):
        read_prior_grasps(tmp_path / "missing.zarr")
    write_prior_grasps(_grasps(), tmp_path / "g.zarr")
    shutil.rmtree(tmp_path / "g.zarr" / "sd")
    with pytest.raises(ValueError, match=r"g.zarr: missing array 'sd'"):
        read_prior_grasps(tmp_path / "g.zarr")
    bad = _grasps()
    bad.pose = bad.pose[:, :50]
    with pytest.raises(ValueError, match="'pose' has shape"):
        write_prior_grasps(bad, tmp_path / "bad.zarr")
    assert not (tmp_path / "bad.zarr").exists()


def test_filter_step_flags_what_the_thresholds_say(tmp_path):
    hand = load_hand("anny")
    g = _grasps(b=40, seed=1)
    g.pose[:, 6:] = hand.assets.presets["relaxed"][6:]  # within the joint limits
    write_prior_grasps(g, tmp_path / "old.zarr")
    with pytest.raises(ValueError, match="lacks the hand's 'joint_limits'"):  # the filter needs the hand's limits
        filter_prior_grasps(tmp_path / "old.zarr", {}, tmp_path / "x.zarr")
    g.attrs = {**g.attrs, "joint_limits": hand.assets.joint_limits.tolist()}  # as the synthesis writes them
    write_prior_grasps(g, tmp_path / "raw.zarr")
    thresholds = {"max_pv": 5e-6, "max_sd": 0.025, "max_contact_distance": 0.005, "max_fc": 0.5, "max_dis": 0.6,
                  "max_pen": 0.7}
    f = filter_prior_grasps(tmp_path / "raw.zarr", thresholds, tmp_path / "f.zarr")
    expect = ((g.pv < 5e-6) & (g.sd < 0.025) & (g.contact_distance <= 0.005) & (g.energies["fc"] < 0.5)
              & (g.energies["dis"] < 0.6) & (g.energies["pen"] < 0.7))
    assert 0 < expect.sum() < 40
    np.testing.assert_array_equal(f.passed, expect)
    back = read_prior_grasps(tmp_path / "f.zarr", filtered=True)
    np.testing.assert_array_equal(back.passed, expect)
    assert back.attrs["rejections"]["passed"] == expect.sum()
    df = summarize_prior_grasps([tmp_path / "f.zarr"], tmp_path / "summary.csv")
    assert df.accepted.tolist() == [expect.sum()] and df.fail_sd.tolist() == [int((g.sd >= 0.025).sum())]
    with pytest.raises(ValueError, match="unknown settings"):
        filter_prior_grasps(tmp_path / "raw.zarr", {"max_sdd": 1}, tmp_path / "x.zarr")


def test_synthesis_and_metrics_of_one_brick(tmp_path):
    cube = make_brick("cube")
    cube.apply_translation(-cube.center_mass)
    obj = tmp_path / "brick-cube"
    obj.mkdir()
    cube.export(obj / "mesh.obj")
    cube.convex_hull.export(obj / "collision.obj")
    record_object_files(obj, {"name": "brick-cube"}, ["mesh.obj", "collision.obj"])
    hand = load_hand("anny")
    syn = {"batch": 6, "iterations": 30, "refine_iterations": 10, "plane_fraction": 0.5, "step_decay_every": 8,
           "temperature_decay_every": 2}
    g = make_prior_grasps(obj, hand, "anny", syn, {"spacing": 0.003}, {}, 0.001, "down", 0, tmp_path / "raw.zarr",
                          cache_dir=tmp_path / "cache")
    assert len(g) == 6 and (g.plane[:3, 2] == 1).all() and (g.plane[3:] == 0).all()
    assert list((tmp_path / "cache" / "sdf").glob("*.npz")), "the SDF grid is cached"
    assert np.isfinite(g.sd).all() and (g.sd >= 0).all() and (g.pv >= 0).all()
    assert g.attrs["timing"]["synthesis"] > 0 and g.attrs["config"]["synthesis"]["batch"] == 6
    again = make_prior_grasps(obj, hand, "anny", syn, {"spacing": 0.003}, {}, 0.001, "down", 0,
                              tmp_path / "again.zarr", cache_dir=tmp_path / "cache")
    np.testing.assert_array_equal(again.pose, g.pose)
    np.testing.assert_array_equal(again.sd, g.sd)
    assert g.attrs["screen"] is None and np.isfinite(g.sd).all()
    # Screened: SD only for the grasps that pass the energy and joint checks, each measured as without the
    # screen, so the filter accepts the same grasps. A dis bound at the median splits the batch.
    screen = {"max_fc": 20.0, "max_dis": float(np.median(g.energies["dis"])), "max_pen": 1.0, "joint_tolerance": 0.0}
    s = make_prior_grasps(obj, hand, "anny", syn, {"spacing": 0.003}, {}, 0.001, "down", 0, tmp_path / "screened.zarr",
                          cache_dir=tmp_path / "cache", screen=screen)
    simulated = np.isfinite(s.sd)
    assert 0 < simulated.sum() < 6 and s.attrs["screen"] == screen
    lim = hand.joint_limits.numpy().reshape(45, 2)
    in_limits = ((g.pose[:, 6:] >= lim[:, 0]) & (g.pose[:, 6:] <= lim[:, 1])).all(1)
    e = g.energies
    expect = (e["fc"] < screen["max_fc"]) & (e["dis"] < screen["max_dis"]) & (e["pen"] < screen["max_pen"]) & in_limits
    np.testing.assert_array_equal(simulated, expect)
    np.testing.assert_array_equal(s.pose, g.pose)
    np.testing.assert_array_equal(s.pv, g.pv)
    np.testing.assert_array_equal(s.contact_distance, g.contact_distance)
    np.testing.assert_array_equal(s.sd[simulated], g.sd[simulated])
    loose = {**screen, "max_sd": 0.1, "max_pv": 1e-4}
    f_all = filter_prior_grasps(tmp_path / "raw.zarr", loose, tmp_path / "f-all.zarr")
    f_scr = filter_prior_grasps(tmp_path / "screened.zarr", loose, tmp_path / "f-scr.zarr")
    np.testing.assert_array_equal(f_scr.passed, f_all.passed)
    assert f_scr.attrs["rejections"]["unsimulated"] == (~simulated).sum()
    with pytest.raises(ValueError, match="could accept grasps never simulated"):
        filter_prior_grasps(tmp_path / "screened.zarr", {**loose, "max_fc": 30.0}, tmp_path / "x.zarr")
    with pytest.raises(ValueError, match="only .* can screen grasps before SD"):
        make_prior_grasps(obj, hand, "anny", syn, {"spacing": 0.003}, {}, 0.001, "down", 0, tmp_path / "x.zarr",
                          cache_dir=tmp_path / "cache", screen={**screen, "max_sd": 0.03})
    assert object_seed(0, "brick-cube") != object_seed(0, "brick-arch") != object_seed(1, "brick-arch")
