"""python -m tohgs.export: a prediction store's grasps as hand meshes (OBJ, PLY, GLB) that load with the
store's vertices, and as MANO-layout parameters that pose the same hands again."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from tohgs.data.predictions import write_predictions
from tohgs.export import export_meshes, export_npz, grasp_vectors, main, split_grasps
from tohgs.hand import load_hand_assets


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, Path, object]:
    """A results folder with the anny hand and one prediction store of 2 configurations x 3 grasps."""
    root = tmp_path_factory.mktemp("run") / "results"
    assets = load_hand_assets("anny")
    (root / "hand").mkdir(parents=True)
    assets.save(root / "hand" / "hand.npz")
    rng = np.random.default_rng(0)
    c, s = 2, 3
    grasp = np.concatenate([rng.uniform(-0.3, 0.3, (c, s, 3)), rng.normal(0, 0.8, (c, s, 3)),
                            rng.normal(0, 0.25, (c, s, 45))], axis=-1).astype(np.float32)
    goal = grasp.copy()
    goal[..., :3] += np.float32([0.1, -0.2, 0.05])
    arrays = {"object_id": np.array([1, 0]), "config_index": np.array([0, 4]), "contact": rng.uniform(0, 1, (c, s, 7)),
              "grasp_init": grasp, "grasp_goal": goal, "kept": np.array([[True, False, True], [True, True, True]])}
    store = root / "predictions" / "placing" / "ours.zarr"
    write_predictions(arrays, {"task": "placing", "method": "ours", "objects": ["ycb-a", "dir-b"]}, store)
    return root, store, assets


@pytest.mark.parametrize("fmt", ["obj", "ply", "glb"])
def test_each_mesh_file_loads_with_the_stores_vertices(run, tmp_path, fmt):
    root, store, assets = run
    files = export_meshes(store, tmp_path, fmt)
    assert len(files) == 2 * 3 * 2 and files[0].name == f"dir-b_c0_s0_init.{fmt}"
    from tohgs.data.predictions import read_predictions

    arrays, _ = read_predictions(store)
    for path in (files[0], files[-1]):  # dir-b config 0 sample 0 init; ycb-a config 4 sample 2 goal
        c, s, pose = (0, 0, "init") if path == files[0] else (1, 2, "goal")
        want = assets.vertices(arrays[f"grasp_{pose}"][c, s][None].astype(np.float64))[0]
        mesh = trimesh.load(path, force="mesh", process=False)
        assert mesh.vertices.shape == want.shape and len(mesh.faces) == len(assets.faces)
        assert np.abs(mesh.vertices - want).max() < 1e-6, f"{path.name}: not the store's hand"
    assert files[-1].name == f"ycb-a_c4_s2_goal.{fmt}"


def test_the_parameters_round_trip_to_the_stored_hands(run, tmp_path):
    root, store, assets = run
    path = export_npz(store, tmp_path)
    assert path.name == "placing_ours.npz"
    with np.load(path, allow_pickle=False) as z:
        params = {k: z[k] for k in z.files}
    assert str(params["hand"]) == "anny" and list(params["objects"]) == ["ycb-a", "dir-b"]
    assert params["init_hand_pose"].shape == (2, 3, 45) and params["init_betas"].shape == (2, 3, 10)
    assert params["kept"].tolist() == [[True, False, True], [True, True, True]]
    from tohgs.data.predictions import read_predictions

    arrays, _ = read_predictions(store)
    for pose in ("init", "goal"):
        back = grasp_vectors(params, f"{pose}_")
        stored = arrays[f"grasp_{pose}"].astype(np.float64)
        np.testing.assert_array_equal(back, stored)
        again = assets.vertices(back.reshape(-1, 51))
        want = assets.vertices(stored.reshape(-1, 51))
        assert np.abs(again - want).max() <= 1e-6
    np.testing.assert_array_equal(params["faces"], assets.faces)
    moved = dict(params, goal_betas=np.ones_like(params["goal_betas"]))
    with pytest.raises(ValueError, match="betas"):
        grasp_vectors(moved, "goal_")
    with pytest.raises(ValueError, match="51"):
        split_grasps(np.zeros((2, 50)))


def test_the_command_line_writes_and_names_its_errors(run, tmp_path, capsys):
    root, store, _ = run
    assert main([str(store), "--format", "ply", "--pose", "goal", "--out", str(tmp_path / "m")]) == 0
    assert len(list((tmp_path / "m").glob("*_goal.ply"))) == 6 and not list((tmp_path / "m").glob("*_init.ply"))
    assert main([str(store), "--format", "npz", "--out", str(tmp_path / "p"), "--hand", str(tmp_path / "none.npz")]) == 1
    assert "none.npz: no hand file" in capsys.readouterr().err


@pytest.mark.slow
def test_a_glb_with_its_scene_holds_the_hand_the_target_and_the_scene(smoke_run, tmp_path):
    from tohgs.data.predictions import read_predictions
    from tohgs.hand import HandAssets

    store = smoke_run / "results" / "predictions" / "placing" / "ours.zarr"
    files = export_meshes(store, tmp_path, "glb", ("goal",), with_scene=True)
    scene = trimesh.load(files[0])
    names = set(scene.geometry)
    assert {"hand", "target"} <= names and any(n.startswith("support:") for n in names), names
    transform, geometry = scene.graph["hand"]
    hand = scene.geometry[geometry].copy().apply_transform(transform)
    arrays, _ = read_predictions(store)
    assets = HandAssets.load(smoke_run / "results" / "hand" / "hand.npz")
    want = assets.vertices(arrays["grasp_goal"][0, :1].astype(np.float64))[0]
    assert np.abs(hand.vertices - want).max() < 1e-6
    with pytest.raises(ValueError, match="--with-scene needs --format glb"):
        export_meshes(store, tmp_path, "obj", with_scene=True)
