"""tohgs grasp (tohgs.own_object): a mesh the run never saw gets grasps from the run's trained models, with its
exports (meshes that load with the store's hands, parameters that pose them again), its metrics and its
page; bad requests are refused naming the file and the fix, with nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh

from tohgs.own_object import OwnObjectError, grasp_own_object, main

REPO = Path(__file__).resolve().parent.parent
SMOKE = ".test/config/config.yaml"


def _capsule(path: Path, scale: float = 1.0) -> Path:
    mesh = trimesh.creation.capsule(height=0.06, radius=0.025)
    mesh.apply_scale(scale)
    mesh.export(path)
    return path


def test_bad_requests_name_the_file_and_write_nothing(tmp_path):
    results = tmp_path / "results"
    mesh = _capsule(tmp_path / "cap.obj")
    out = tmp_path / "out"
    cases = [
        (dict(mesh=tmp_path / "none.obj"), "none.obj: no such mesh file"),
        (dict(mesh=tmp_path / "cap.txt"), "no such mesh file"),
        (dict(task="pouring"), "--task 'pouring': one of placing, stacking, shelving"),
        (dict(), "supports.json: missing; .*results is not a finished run's results folder"),
    ]
    for change, message in cases:
        kwargs = dict(mesh=mesh, task="placing", out=out, results=results) | change
        with pytest.raises(OwnObjectError, match=message):
            grasp_own_object(**kwargs)
        assert not out.exists()
    (tmp_path / "cap.txt").write_text("v 0 0 0\n")
    with pytest.raises(OwnObjectError, match=r"\.obj, \.stl or \.ply, not '\.txt'"):
        grasp_own_object(tmp_path / "cap.txt", "placing", out, results)
    out.mkdir()
    with pytest.raises(OwnObjectError, match="out: the output folder exists"):
        grasp_own_object(mesh, "placing", out, results)


@pytest.mark.slow
def test_a_new_mesh_gets_grasps_exports_metrics_and_a_page(smoke_run, tmp_path, monkeypatch):
    from tohgs.data.predictions import read_predictions
    from tohgs.export import grasp_vectors
    from tohgs.hand import HandAssets

    monkeypatch.chdir(tmp_path)  # elsewhere: the run's relative cache_dir is taken in the run's folder
    results = smoke_run / "results"
    # in millimetres: the objects stage rescales it into the run's size range and the summary says by what
    mesh = _capsule(tmp_path / "my cup.stl", scale=1000.0)
    out = tmp_path / "grasps"
    summary = grasp_own_object(mesh, "placing", out, results, [smoke_run / SMOKE], n=4, configs=2,
                               formats=("obj", "ply", "glb", "npz"))
    assert summary["object"] == "dir-my-cup" and summary["configurations"] == 2
    assert summary["scale"] < 0.01 and 0.05 < max(summary["extents_m"]) < 0.3  # mm -> m, by the size range
    assert json.loads((out / "summary.json").read_text()) == summary
    arrays, attrs = read_predictions(out / "predictions" / "placing" / "ours.zarr")
    assert attrs["objects"] == ["dir-my-cup"] and arrays["grasp_init"].shape[:2] == (2, 4)
    metrics = pd.read_parquet(out / "metrics" / "placing" / "ours.parquet")
    assert len(metrics) == len(summary["grasps"]) == 8 and metrics.sd.notna().all() and (metrics.pv >= 0).all()
    # the hands are at the object: their centroids within 15 cm of its centre at the initial pose
    hand = HandAssets.load(results / "hand" / "hand.npz")
    from tohgs.data.scenes import read_scenes

    scenes = read_scenes(out / "scenes" / "placing" / "dir-my-cup.zarr")
    for c, ci in enumerate(arrays["config_index"]):
        centroids = hand.vertices(arrays["grasp_init"][c].astype(np.float64)).mean(1)
        assert np.linalg.norm(centroids - scenes.target_init_pose[int(ci)][:3], axis=-1).max() < 0.15
    # every export: one file per grasp and pose, each the store's hand; the parameters pose them again
    for fmt in ("obj", "ply", "glb"):
        files = sorted((out / "export").glob(f"*.{fmt}"))
        assert len(files) == 2 * 4 * 2
        got = trimesh.load(out / "export" / f"dir-my-cup_c{int(arrays['config_index'][0])}_s3_goal.{fmt}",
                           force="mesh", process=False).vertices
        want = hand.vertices(arrays["grasp_goal"][0, 3][None].astype(np.float64))[0]
        assert np.abs(got - want).max() < 1e-6
    with np.load(out / "export" / "placing_ours.npz", allow_pickle=False) as z:
        back = grasp_vectors({k: z[k] for k in z.files}, prefix="init_")
    assert np.abs(hand.vertices(back.reshape(-1, back.shape[-1]))
                  - hand.vertices(arrays["grasp_init"].reshape(-1, back.shape[-1]).astype(np.float64))).max() < 1e-6
    assert (out / "viewer.html").stat().st_size > 100_000  # the scene, embedded (rendered below, with chromium)
    assert (out / "grasps.png").stat().st_size > 10_000
    # its configurations, as the scene file it wrote, give the same scenes back; one with an obstacle moved
    # into the target is refused, naming the configuration, the bodies and the depth
    import yaml

    from tohgs.scene_file import SceneFileError

    again = tmp_path / "again"
    grasp_own_object(mesh, "placing", again, results, [smoke_run / SMOKE], n=2, formats=(), viewer=False,
                     scene=out / "scene.yaml")
    first, second = (read_scenes(d / "scenes" / "placing" / "dir-my-cup.zarr") for d in (out, again))
    assert len(second) == 2 and np.abs(first.target_goal_pose - second.target_goal_pose).max() < 1e-5
    assert [second.obstacles(c)[k][0] for c in range(2) for k in range(len(second.obstacles(c)))] == \
        [first.obstacles(c)[k][0] for c in range(2) for k in range(len(first.obstacles(c)))]
    doc = yaml.safe_load((out / "scene.yaml").read_text())
    entry = doc["configurations"][1]
    entry["obstacles"] = [{"object": first.obstacles(1)[0][0], "pose": entry["init"]}]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(SceneFileError, match=r"configurations\[1\]: at the initial pose the target reaches .* mm into "
                                             r"obstacle 0"):
        grasp_own_object(mesh, "placing", tmp_path / "bad", results, [smoke_run / SMOKE],
                         scene=tmp_path / "bad.yaml")
    assert not (tmp_path / "bad").exists()
    # the same object again into the same folder: refused, the first result intact
    with pytest.raises(OwnObjectError, match="output folder exists"):
        grasp_own_object(mesh, "placing", out, results, [smoke_run / SMOKE])
    assert (out / "summary.json").is_file()
    assert not (tmp_path / "results").exists()  # no cache beside the working directory: the run's served


@pytest.mark.slow
def test_methods_without_models_or_with_ground_truth_are_refused(smoke_run, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(smoke_run)
    mesh = _capsule(tmp_path / "cap.obj")
    args = [str(mesh), "--task", "placing", "--results", "results", "--configfile", SMOKE, "--out", str(tmp_path / "o")]
    assert main([*args, "--method", "dataset"]) == 2
    assert "reads the test configurations' ground-truth grasps" in capsys.readouterr().err
    assert main([*args, "--method", "no-such-method"]) == 2
    assert "not a method of the run's config" in capsys.readouterr().err
    models = smoke_run / "results" / "models" / "placing"
    hidden = models.parent / "placing-hidden"
    models.rename(hidden)
    try:
        assert main(args) == 2
        err = capsys.readouterr().err
        assert "has no trained models" in err and "make reproduce TARGET=results/models/placing/" in err
    finally:
        hidden.rename(models)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_page_renders_offline_in_chromium(smoke_run, tmp_path, monkeypatch):
    import viewer_browser as vb

    if not vb.chromium():
        pytest.skip("no chromium (make test SYSTEM_PACKAGES=yes installs it)")
    monkeypatch.chdir(smoke_run)
    out = tmp_path / "grasps"
    grasp_own_object(_capsule(tmp_path / "cap.obj"), "shelving", out, smoke_run / "results", [SMOKE], n=2,
                     formats=())
    requests: list[str] = []
    with vb.browser() as ctx:
        page = vb.open_page(ctx, (out / "viewer.html").resolve().as_uri(), requests)
        shot = vb.wait_for_scene(page)
    vb.save(shot, tmp_path / "page.png")
    assert vb.scene_fraction(shot) > 0.05, "the page shows no scene"
    assert not vb.outside(requests), vb.outside(requests)

