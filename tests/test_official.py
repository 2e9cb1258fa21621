"""The official TOHGS dataset: import a small synthetic tree in the official format, export predictions in the
official evaluation's format, and compare (tohgs/official/, docs/official_dataset.md)."""

from __future__ import annotations

import hashlib
import io
import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tohgs.official.exporter import export_official
from tohgs.official.format import NO_PRIOR, load_official_npy, load_official_pickle, shift_grasp, to_official_pose
from tohgs.official.importer import import_official, read_import
from tohgs.data.predictions import write_predictions
from tohgs.data.scenes import read_scenes
from tohgs.data.task_grasps import read_task_grasps
from tohgs.geometry.grasp import pose_matrix, transform_grasp
from tohgs.hand import load_hand_assets

from synthetic_official import DS, TABLE_TOP, make_official_tree


@pytest.fixture(scope="module")
def hand():
    return load_hand_assets("anny")


# --- the synthetic official tree ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> dict:
    return make_official_tree(tmp_path_factory.mktemp("official"))


@pytest.fixture(scope="module")
def imported(tree, hand, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("imported")
    report = import_official(tree["root"], out, hand)
    return {**tree, "out": out, "report": report}


# --- the importer ---------------------------------------------------------------------------------------

def test_counts(imported):
    tasks = imported["report"].tasks
    assert tasks["placing"] == {"files": 2, "rows": 5, "configurations": 4, "test_files": 1,
                                "test_configurations": 3, "targets": 2}
    assert tasks["shelving"] == {"files": 1, "rows": 2, "configurations": 2, "test_files": 1,
                                 "test_configurations": 2, "targets": 1}
    assert tasks["stacking"] == {"files": 3, "rows": 4, "configurations": 4, "test_files": 1,
                                 "test_configurations": 2, "targets": 3}
    assert imported["report"].objects == {"ok": 6, "rejected": 0}


def test_the_workflow_reads_the_splits_and_the_hand(imported):
    """Per task the official split (train.txt, val.txt, the test JSONs' targets; Stacking's hard-coded one),
    and the hand, as the workflow reads them (:func:`read_import`); an older import without them is refused."""
    data = read_import(imported["out"])
    assert data.hand == "anny" and data.n_problems == 2
    assert data.splits == {
        "placing": {"train": ["off-mug-a"], "val": ["off-can-b"], "test": ["off-can-b"]},
        "shelving": {"train": [], "val": ["off-mug-a"], "test": ["off-mug-a"]},  # train.txt's only file is unreadable
        "stacking": {"train": ["off-brick-a", "off-brick-c"], "val": ["off-brick-f"], "test": ["off-brick-f"]}}
    assert data.targets("placing") == ["off-can-b", "off-mug-a"]
    assert "off-box-c" in data.objects  # an obstacle only: in the catalog, in no split
    old = json.loads((imported["out"] / "import_report.json").read_text())
    del old["splits"]
    copy = imported["out"].parent / "old-import"
    (copy / "objects").mkdir(parents=True)
    (copy / "import_report.json").write_text(json.dumps(old))
    (copy / "objects/catalog.csv").write_text((imported["out"] / "objects/catalog.csv").read_text())
    with pytest.raises(ValueError, match="import again"):
        read_import(copy)
    with pytest.raises(FileNotFoundError, match="python -m tohgs.official import"):
        read_import(copy / "nothing")
    older = imported["out"].parent / "older-import"  # objects without the checksums of their files
    shutil.copytree(imported["out"], older)
    meta = json.loads((older / "objects/off-can-b/meta.json").read_text())
    del meta["files"]
    (older / "objects/off-can-b/meta.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"off-can-b/meta\.json: no checksums of the object's files \(an import by an "
                                         r"older tohgs\): import again"):
        read_import(older)


def test_bad_files_are_counted_and_named(imported):
    report = imported["report"]
    problems = {p["path"]: p for p in report.problems}
    assert report.n_problems == 2
    assert set(problems) == {f"{DS}/placing/broken.npy", f"{DS}/shelving/uneven.npy"}
    assert problems[f"{DS}/placing/broken.npy"]["kind"] == "unreadable"
    assert "unequal list lengths" in problems[f"{DS}/shelving/uneven.npy"]["reason"]
    assert "goal_pose 1" in problems[f"{DS}/shelving/uneven.npy"]["reason"]
    written = json.loads((imported["out"] / "import_report.json").read_text())
    assert written["n_problems"] == 2 and {p["path"] for p in written["problems"]} == set(problems)


def test_checksums_match_sha256(imported):
    root, lines = imported["root"], (imported["out"] / "checksums.sha256").read_text().splitlines()
    digests = dict(reversed(line.split("  ", 1)) for line in lines)
    assert len(digests) == imported["report"].files_read
    assert {f"{DS}/placing/mug_a.npy", f"{DS}/placing/broken.npy", f"{DS}/placing/train.txt",
            f"{DS}/shelving/test/mug_a.json", "models/table/table.obj",
            "models/meshdata/mug_a/coacd/decomposed_scaled.obj"} <= set(digests)
    for rel, digest in digests.items():
        assert digest == hashlib.sha256((root / rel).read_bytes()).hexdigest(), rel


def _offsets(out: Path) -> dict:
    return {p.parent.name: np.asarray(json.loads(p.read_text()).get("official_offset", [0, 0, 0]))
            for p in (out / "objects").glob("*/meta.json")}


def test_placing_scenes_and_grasps_equal_the_source(imported, hand):
    src, out = imported["src"]["placing/mug_a"], imported["out"]
    scenes = read_scenes(out / "scenes/placing/off-mug-a.zarr")
    assert len(scenes) == 2 and scenes.attrs["official"]["index"] == [0, 2]
    assert scenes.attrs["official"]["table_top"] == pytest.approx(TABLE_TOP)
    off = _offsets(out)
    assert off["off-mug-a"] == pytest.approx(np.average([[0.01, -0.02, 0.03], [0.06, -0.02, 0.03]], axis=0,
                                                        weights=[0.06 * 0.04 * 0.08, 0.04 * 0.03 * 0.03]), abs=2e-4)
    for c, row in enumerate([0, 2]):
        back = to_official_pose(scenes.target_init_pose[c], off["off-mug-a"], TABLE_TOP)
        np.testing.assert_allclose(back, src["init_pose"][row], atol=1e-9)
        np.testing.assert_allclose(to_official_pose(scenes.target_goal_pose[c], off["off-mug-a"], TABLE_TOP),
                                   src["goal_pose"][row], atol=1e-9)
        obs = scenes.obstacles(c)
        assert [scenes.attrs["official"]["names"][n] for n, _ in obs] == src["obstacle_name"][row]
        for (n, p), q in zip(obs, src["obstacle_pose"][row]):
            np.testing.assert_allclose(to_official_pose(p, off[n], TABLE_TOP), q, atol=1e-9)
        assert scenes.support(c)[0] == "table" and scenes.base(c) is None
    g, attrs = read_task_grasps(out / "grasps/task/placing/off-mug-a.zarr")
    assert g["config"].tolist() == [0, 0, 1] and g["kept_per_config"].tolist() == [2, 1]
    assert (g["prior_index"] == NO_PRIOR).all() and attrs["official"]["row"] == [0, 1, 2]
    recon = np.concatenate(src["recon_param"])
    np.testing.assert_allclose(shift_grasp(g["grasp_init"], TABLE_TOP), recon, atol=1e-5)
    # The goal grasp is the initial hand carried by T_goal T_init^-1 (official poses, official frame).
    for k, row in enumerate([0, 1, 2]):
        T = pose_matrix(src["goal_pose"][row]) @ np.linalg.inv(pose_matrix(src["init_pose"][row]))
        v_init = hand.vertices(recon[k:k + 1].astype(np.float64))[0]
        v_goal = hand.vertices(shift_grasp(g["grasp_goal"][k:k + 1], TABLE_TOP))[0]
        np.testing.assert_allclose(v_goal, v_init @ T[:3, :3].T + T[:3, 3], atol=1e-5)


def test_shelving_and_stacking_quirks(imported):
    out, src = imported["out"], imported["src"]
    shelving = read_scenes(out / "scenes/shelving/off-mug-a.zarr")
    assert shelving.supports == ["shelf-shelf01"] and len(shelving) == 2
    np.testing.assert_allclose(to_official_pose(shelving.support(0)[1], None, TABLE_TOP),
                               src["shelving/mug_a"]["shelf_pose"][0], atol=1e-9)
    test = read_scenes(out / "test_scenes/shelving/off-mug-a.zarr")
    assert len(test) == 2 and test.attrs["official"]["file"] == f"{DS}/shelving/test/mug_a.json"
    supports = json.loads((out / "objects/supports/supports.json").read_text())["supports"]
    shelf = next(s for s in supports if s["name"] == "shelf-shelf01")
    assert len(shelf["boxes"]) == 4 and shelf["params"]["box_fill"] == pytest.approx(1.0, abs=1e-6)
    stacking = read_scenes(out / "scenes/stacking/off-brick-a.zarr")
    g, _ = read_task_grasps(out / "grasps/task/stacking/off-brick-a.zarr")
    assert len(stacking) == 2 and stacking.base(0)[0] == "off-brick-c" and len(g["config"]) == 2
    off = _offsets(out)
    np.testing.assert_allclose(to_official_pose(stacking.base(1)[1], off["off-brick-c"], TABLE_TOP),
                               src["stacking/A"]["init"][1][1], atol=1e-9)
    np.testing.assert_allclose(shift_grasp(g["grasp_init"], TABLE_TOP),
                               np.concatenate(src["stacking/A"]["recon_parms"]), atol=1e-5)
    catalog = pd.read_csv(out / "objects/catalog.csv", keep_default_na=False).set_index("name")
    assert catalog.loc["off-mug-a", "split"] == "train"  # placing's train list decides (first read)
    assert catalog.loc["off-can-b", "split"] == "test"  # their val is their evaluation set
    assert catalog.loc["off-box-c", "split"] == "" and catalog.loc["off-brick-f", "split"] == "test"
    assert (catalog.status == "ok").all() and (catalog.source == "official").all()
    mesh_dir = out / "objects/off-can-b"
    assert {p.name for p in mesh_dir.iterdir()} == {"mesh.obj", "collision.obj", "object.urdf", "meta.json"}
    assert off["off-can-b"] == pytest.approx([0.0, 0.0, 0.05], abs=1e-9)


def test_scenes_load_into_the_simulator(imported):
    """The imported objects, supports and scenes are what the simulation stages load."""
    from tohgs.assets.supports import read_supports
    from tohgs.sim.scenes import load_configuration
    from tohgs.sim.world import World

    out = imported["out"]
    supports = read_supports(out / "objects/supports/supports.json")
    world = World()
    try:
        for task, name in (("placing", "off-mug-a"), ("shelving", "off-mug-a"), ("stacking", "off-brick-a")):
            scenes = read_scenes(out / f"scenes/{task}/{name}.zarr")
            bodies = load_configuration(world, scenes, 0, out / "objects", supports)
            assert bodies["target"] is not None and len(bodies["obstacles"]) == len(scenes.obstacles(0))
            assert (bodies["base"] is not None) == (task == "stacking")
    finally:
        world.close()


# --- the restricted loader ------------------------------------------------------------------------------

class _Evil:
    def __reduce__(self):
        import os

        return (os.system, ("echo should-never-run",))


def test_restricted_loader_refuses_code():
    evil = pickle.dumps(_Evil())  # pickling only names os.system; nothing runs
    with pytest.raises(ValueError, match=r"refusing global '(os|posix)\.system'"):
        load_official_pickle(evil, "evil.pkl")
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|O", "fortran_order": False, "shape": ()})
    with pytest.raises(ValueError, match=r"evil\.npy: refusing global"):
        load_official_npy(header.getvalue() + evil, "evil.npy")  # the header writes the magic
    with pytest.raises(ValueError, match="refusing global 'collections.OrderedDict'"):
        load_official_pickle(pickle.dumps(__import__("collections").OrderedDict(a=1)), "x")
    ok = io.BytesIO()
    np.save(ok, {"a": [np.arange(3.0)], "b": "name"}, allow_pickle=True)
    d = load_official_npy(ok.getvalue())
    assert d["b"] == "name" and np.array_equal(d["a"][0], np.arange(3.0))


# --- the round trip -------------------------------------------------------------------------------------

@pytest.mark.parametrize("task,stem,target", [("placing", "can_b", "off-can-b"), ("shelving", "mug_a", "off-mug-a"),
                                              ("stacking", "F", "off-brick-f")])
def test_round_trip(imported, hand, tmp_path, task, stem, target):
    """import -> predictions made of imported grasps -> export -> read back -> the official poses and the
    hand's vertices of the same grasps."""
    out = imported["out"]
    test = read_scenes(out / f"test_scenes/{task}/{target}.zarr")
    g, _ = read_task_grasps(out / f"grasps/task/{task}/{target}.zarr")
    c_n, s_n = len(test), 2
    wrist = hand.rest_joints[0]
    grasp_init = np.stack([g["grasp_init"][np.arange(s_n) % len(g["grasp_init"])]] * c_n).astype(np.float64)
    grasp_goal = np.stack([transform_grasp(grasp_init[c], pose_matrix(test.target_goal_pose[c])
                                           @ np.linalg.inv(pose_matrix(test.target_init_pose[c])), wrist)
                           for c in range(c_n)])
    kept = np.ones((c_n, s_n), bool)
    kept[0, 1] = False  # a discarded grasp is not exported
    pred = tmp_path / f"{task}.zarr"
    rev = np.arange(c_n)[::-1]  # the store's rows in another order than the official configurations
    write_predictions({"object_id": np.zeros(c_n), "config_index": rev, "contact": np.zeros((c_n, s_n, 4)),
                       "grasp_init": grasp_init[rev], "grasp_goal": grasp_goal[rev], "kept": kept[rev]},
                      {"task": task, "method": "test", "objects": [target]}, pred)
    written = export_official(pred, out / "test_scenes", hand, tmp_path / "result" / "run")
    assert list(written) == [stem] and written[stem].name == f"{stem}.npy"
    back = load_official_npy(written[stem].read_bytes(), str(written[stem]))
    src = imported["src"][f"{task}/test/{stem}"]
    assert back["config"] == [c for c in range(c_n) for s in range(s_n) if kept[c, s]]
    assert back["n_hand_vertices"] == len(hand.rest_vertices) == back["init_hand_vertex"][0].shape[0]
    grasps = np.concatenate([grasp_init[c, kept[c]] for c in range(c_n)])  # the store's order reversed back
    v_ref = hand.vertices(shift_grasp(grasps.astype(np.float32), TABLE_TOP))
    np.testing.assert_allclose(np.stack(back["init_hand_vertex"]), v_ref, atol=1e-5)
    for k, c in enumerate(back["config"]):
        init_key, goal_key = ("init", "goal") if task == "stacking" else ("init_pose", "goal_pose")
        if task == "stacking":
            assert back["init_pose"][k][0] == src[init_key][c][0] and back["init_pose"][k][2] == src[init_key][c][2]
            np.testing.assert_allclose(back["init_pose"][k][1], src[init_key][c][1], atol=1e-9)
            p_init, p_goal = back["init_pose"][k][3], back["goal_pose"][k][3]
        else:
            p_init, p_goal = back["init_pose"][k], back["goal_pose"][k]
            assert back["obstacle_name"][k] == src["obstacle_name"][c]
            np.testing.assert_allclose(np.reshape(back["obstacle_pose"][k], (-1, 7)),
                                       np.reshape(src["obstacle_pose"][c], (-1, 7)), atol=1e-9)
            assert back["grasped_obj"] == stem
        np.testing.assert_allclose(p_init, src[init_key][c] if task != "stacking" else src[init_key][c][3], atol=1e-9)
        np.testing.assert_allclose(p_goal, src[goal_key][c] if task != "stacking" else src[goal_key][c][3], atol=1e-9)
        if task == "shelving":
            assert back["shelf_name"][k] == src["shelf_name"][c]
            np.testing.assert_allclose(back["shelf_pose"][k], src["shelf_pose"][c], atol=1e-9)
        # The official evaluation's goal hand: the initial hand carried by the official poses.
        T = pose_matrix(p_goal) @ np.linalg.inv(pose_matrix(p_init))
        np.testing.assert_allclose(back["goal_hand_vertex"][k], back["init_hand_vertex"][k] @ T[:3, :3].T + T[:3, 3],
                                   atol=2e-5)


# --- bad input the importer reports instead of importing or crashing ----------------------------------------

def _tree_copy(tree: dict, tmp_path: Path) -> Path:
    root = tmp_path / "official"
    shutil.copytree(tree["root"], root)
    return root


def _problems(report) -> dict[str, dict]:
    return {p["path"]: p for p in report.problems}


def test_names_that_sanitise_alike_are_a_problem_naming_both_files(tree, hand, tmp_path):
    """``Shelf01``/``shelf01`` (shelves) and ``Box_C``/``box_c`` (objects) once merged silently (the scenes of
    one used the other's mesh) or stopped the import; now the first in sorted order keeps the name and the
    other is a problem naming both files, left out with the rows that use it."""
    from synthetic_official import _write_boxes

    root = _tree_copy(tree, tmp_path)
    md, ds = root / "models", root / DS
    _write_boxes(md / "selected_shelf/Shelf01/coacd/decomposed.obj", [((0, 0, 0.01), (0.5, 0.3, 0.02))])
    _write_boxes(md / "meshdata/Box_C/coacd/decomposed_scaled.obj", [((0.0, 0.0, 0.0), (0.02, 0.02, 0.02))])
    shelving = dict(tree["src"]["shelving/mug_a"], shelf_name=["Shelf01", "shelf01"])
    np.save(ds / "shelving/mug_a.npy", shelving, allow_pickle=True)
    can_b = dict(tree["src"]["placing/can_b"], obstacle_name=[["Box_C", "mug_a"], []])
    np.save(ds / "placing/can_b.npy", can_b, allow_pickle=True)
    report = import_official(root, tmp_path / "out", hand)
    problems = _problems(report)
    shelf = problems["models/selected_shelf/shelf01/coacd/decomposed.obj"]
    assert shelf["kind"] == "name" and shelf["reason"] == (
        "official shelf 'shelf01' and shelf 'Shelf01' (models/selected_shelf/Shelf01/coacd/decomposed.obj) both "
        "become 'shelf-shelf01': 'shelf01' is left out, with the 3 rows and test configurations that use it")
    box = problems["models/meshdata/box_c/coacd/decomposed_scaled.obj"]
    assert box["kind"] == "name" and "'Box_C' (models/meshdata/Box_C/coacd/decomposed_scaled.obj) both become " \
                                     "'off-box-c'" in box["reason"]
    scenes = read_scenes(tmp_path / "out/scenes/shelving/off-mug-a.zarr")
    assert len(scenes) == 1 and scenes.attrs["official"]["supports"] == {"shelf-shelf01": "Shelf01"}
    supports = json.loads((tmp_path / "out/objects/supports/supports.json").read_text())["supports"]
    assert [s["params"]["official_name"] for s in supports if s["kind"] == "shelf"] == ["Shelf01"]
    mug = read_scenes(tmp_path / "out/scenes/placing/off-can-b.zarr")
    assert mug.attrs["official"]["names"]["off-box-c"] == "Box_C"


def test_the_command_line_writes_what_the_library_writes(tree, hand, tmp_path, capsys):
    """``python -m tohgs.official import`` (its main, in this process) writes the files import_official writes,
    byte for byte, prints the counts and exits 1 when a file could not be used."""
    from tohgs.official.__main__ import main

    rc = main(["import", str(tree["root"]), str(tmp_path / "cli"), "--tasks", "placing", "--hand", "anny"])
    report = import_official(tree["root"], tmp_path / "lib", hand, ["placing"])

    def files(d: Path) -> dict[Path, bytes]:  # the report names its own output folder
        return {p.relative_to(d): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()
                and p.name != "import_report.json"}

    assert files(tmp_path / "cli") == files(tmp_path / "lib") and len(files(tmp_path / "lib")) > 10
    assert rc == 1 and report.n_problems == 1  # the unreadable broken.npy
    assert f"{report.files_read} files read, 1 problems" in capsys.readouterr().out


def test_a_failed_reimport_leaves_the_earlier_import_whole(tree, hand, tmp_path, monkeypatch):
    """A re-import that fails half-way once left new objects next to old scenes and grasps; now an import is
    written into a temporary folder and renamed into place only when complete."""
    import tohgs.official.importer as official

    out = tmp_path / "out"
    import_official(tree["root"], out, hand, ["placing"])
    before = {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    calls = {"n": 0}
    real = official._write_task

    def killed(*a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt("killed half-way")
        return real(*a, **k)

    monkeypatch.setattr(official, "_write_task", killed)
    with pytest.raises(KeyboardInterrupt):
        import_official(tree["root"], out, hand, ["placing"], density=800.0)  # other masses in meta.json
    after = {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert after == before
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no temporary folder left behind
    monkeypatch.setattr(official, "_write_task", real)
    import_official(tree["root"], out, hand, ["placing"], density=800.0)  # a whole re-import replaces it
    assert json.loads((out / "objects/off-can-b/meta.json").read_text())["density"] == 800.0
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine/thesis.tex").write_text("precious")
    with pytest.raises(ValueError, match=r"mine: a non-empty folder that holds no import \(no import_report\.json\)"):
        import_official(tree["root"], tmp_path / "mine", hand, ["placing"])
    assert (tmp_path / "mine/thesis.tex").read_text() == "precious"


def _nested(depth: int, leaf: list) -> list:
    """A list nested ``depth`` times, each level 10 references to the one below: 10^depth leaves that pickle
    into a few hundred bytes."""
    for _ in range(depth):
        leaf = [leaf] * 10
    return leaf


def test_absurd_numbers_and_shapes_are_refused_before_arrays_are_built(tree, hand, tmp_path):
    import tracemalloc

    root = _tree_copy(tree, tmp_path)
    ds = root / DS
    src = tree["src"]["placing/can_b"]
    far = [np.asarray(p).tolist() for p in src["init_pose"]]
    far[1][0] = 1e6
    np.save(ds / "placing/can_b.npy", dict(src, init_pose=far), allow_pickle=True)
    grasps = [g.copy() for g in tree["src"]["placing/mug_a"]["recon_param"]]
    grasps[2][0, 1] = 1e30
    np.save(ds / "placing/mug_a.npy", dict(tree["src"]["placing/mug_a"], recon_param=grasps), allow_pickle=True)
    shelving = tree["src"]["shelving/mug_a"]
    np.save(ds / "shelving/mug_a.npy", dict(shelving, recon_param=[_nested(6, [0.0] * 10)] * 2), allow_pickle=True)
    assert (ds / "shelving/mug_a.npy").stat().st_size < 4000  # 10^7 numbers by reference
    stacking = tree["src"]["stacking/A"]
    pose = stacking["init"][0][1]
    crowd = dict(tree["src"]["placing/mug_a"], obstacle_pose=[[pose] * 1000] * 3, obstacle_name=[["box_c"] * 1000] * 3)
    np.save(ds / "placing/crowd.npy", crowd, allow_pickle=True)
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**7,)})
    (ds / "placing/liar.npy").write_bytes(header.getvalue() + b"\0" * 8)  # declares 80 MB, holds 8 bytes
    (ds / "placing/train.txt").write_text("mug_a.npy\ncrowd.npy\nliar.npy\n")
    tracemalloc.start()
    try:
        report = import_official(root, tmp_path / "out", hand, ["placing", "shelving"])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    problems = _problems(report)
    assert problems[f"{DS}/placing/can_b.npy"]["reason"] == (f"init_pose[1]: position {far[1][:3]} m is beyond 10 m "
                                                            "of the official world's origin")
    assert problems[f"{DS}/placing/mug_a.npy"]["reason"] == (f"recon_param[2]: translation {grasps[2][0, :3].tolist()} "
                                                            "m is beyond 10 m of the official world's origin")
    assert problems[f"{DS}/shelving/mug_a.npy"]["reason"] == ("recon_param[0]: a list of length 10, expected numbers "
                                                             "of shape (1, 51) or (51,)")
    assert problems[f"{DS}/placing/crowd.npy"]["reason"] == "row 0: 1000 obstacle names and 1000 poses, more than 64 obstacles"
    assert problems[f"{DS}/placing/liar.npy"]["reason"] == ("the .npy header declares float64 (10000000,) (80000000 "
                                                           "bytes) but the file holds 8 bytes of data")
    assert peak < 40e6, f"{peak / 1e6:.0f} MB traced: an array was built before its shape was checked"


def test_a_nan_table_vertex_and_a_non_ascii_name_are_reported_not_crashes(tree, hand, tmp_path):
    """A NaN vertex in table.obj once ended the import in ``LinAlgError: SVD did not converge`` naming no file,
    and an official name without an ASCII letter or digit aborted it; now the first is a problem naming the
    file (the official code's nominal table is used) and the second an object named by its CRC-32."""
    from synthetic_official import _write_boxes

    root = _tree_copy(tree, tmp_path)
    table = root / "models/table/table.obj"
    lines = table.read_text().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("v "))
    lines[first] = "v nan nan nan"
    table.write_text("\n".join(lines) + "\n")
    _write_boxes(root / "models/meshdata/日本/coacd/decomposed_scaled.obj", [((0.0, 0.0, 0.0), (0.03, 0.03, 0.03))])
    can_b = dict(tree["src"]["placing/can_b"], obstacle_name=[["box_c", "日本"], []])
    np.save(root / DS / "placing/can_b.npy", can_b, allow_pickle=True)
    report = import_official(root, tmp_path / "out", hand)
    problems = _problems(report)
    assert problems["models/table/table.obj"]["kind"] == "mesh"
    assert problems["models/table/table.obj"]["reason"].startswith("non-finite vertex coordinates; its top is taken at "
                                                                  "z = 0.6 m")
    assert report.table_top == 0.6 and report.tasks["shelving"]["configurations"] == 2
    catalog = pd.read_csv(tmp_path / "out/objects/catalog.csv", keep_default_na=False).set_index("name")
    name = next(n for n in catalog.index if n.startswith("off-u"))
    assert catalog.loc[name, "status"] == "ok" and catalog.loc[name, "source_path"] == \
        "models/meshdata/日本/coacd/decomposed_scaled.obj"
    scenes = read_scenes(tmp_path / "out/scenes/placing/off-can-b.zarr")
    assert scenes.attrs["official"]["names"][name] == "日本"
