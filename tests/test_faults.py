"""Bad input and faults that once got past: each is refused, rejected or repaired with a message that names
the file and the problem (the cases of the issue "Main is red on a fresh machine ... make it robust").

The end-to-end cases (a single store as a target, the margin of the smoke run's training splits) are in
``tests/test_workflow.py``.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from helpers import SETTINGS, TINY
from tohgs.assets.objects import prepare_object, write_catalog
from tohgs.assets.splits import check_split_sizes
from tohgs.assets.sources import ObjectSpec, dir_candidates, pybullet_data_root
from tohgs.config import ConfigError, validate_config
from tohgs.data.build_maps import EmptySplitError, make_map_shard
from tohgs.data.grasps import ENERGY_TERMS, PriorGrasps, read_prior_grasps, write_prior_grasps
from tohgs.data.maps import read_map_shard
from tohgs.data.predictions import read_predictions, write_predictions
from tohgs.data.scenes import SceneSet, read_scenes, write_scenes
from tohgs.data.task_grasps import read_task_grasps, write_task_grasps
from tohgs.io import atomic_dir, atomic_path
from tohgs.models.checkpoint import load_checkpoint, load_component
from tohgs.models.checkpoint import pick_device
from tohgs.models.train import train_component

REPO = Path(__file__).resolve().parent.parent

# ---------------------------------------------------------------------------------------------------------
# Checkpoints never run code.


class _Payload:
    """Unpickling this calls ``Path.touch`` on the marker: what a crafted checkpoint could do."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


@pytest.mark.parametrize("kind", ["checkpoint", "resume"])
def test_a_checkpoint_that_carries_code_is_refused_and_nothing_runs(built, tmp_path, kind):  # noqa: F811
    marker = tmp_path / "ran"
    evil = {"name": "contact_diffuser", "model_config": {}, "state_dict": {}, "x": _Payload(marker)}
    if kind == "checkpoint":
        torch.save(evil, tmp_path / "m.pt")
        with pytest.raises(ValueError, match=r"m\.pt: not a readable checkpoint of plain data; refused"):
            load_component(tmp_path / "m.pt")
    else:
        tmp = built[0]
        torch.save({**evil, "ema": {"step_count": 1}}, tmp_path / "m.pt.resume")
        with pytest.raises(ValueError, match=r"m\.pt\.resume: not a readable checkpoint of plain data"):
            train_component("contact_diffuser", "contact_diffuser", "placing", [tmp / "shard-0.zarr"], TINY["contact_diffuser"], SETTINGS,
                        tmp_path / "m.pt", hand=built[1])
    assert not marker.exists()
    torch.save({"plain": torch.zeros(2), "n": 3}, tmp_path / "ok.pt")  # plain data still loads
    assert load_checkpoint(tmp_path / "ok.pt")["n"] == 3


# ---------------------------------------------------------------------------------------------------------
# A missing or emptied chunk of any store fails with the store's and the array's name.


def _stores(built, tmp: Path) -> dict[str, tuple[Path, str, callable]]:  # noqa: F811
    """One small store of each kind: {kind: (path, an array with non-fill data, reader)}."""
    src = built[0]
    q = np.array([[0, 0, 0, 1.0]] * 2)
    scenes = SceneSet(task="placing", object="brick-cube", target_init_pose=np.c_[np.ones((2, 3)), q],
                      target_goal_pose=np.c_[np.full((2, 3), 2.0), q], support_id=np.zeros(2, np.int32),
                      support_pose=np.c_[np.zeros((2, 3)), q], base_id=-np.ones(2, np.int32),
                      base_pose=np.full((2, 7), np.nan), obstacle_offsets=np.array([0, 1, 1]),
                      obstacle_id=np.zeros(1, np.int32), obstacle_pose=np.c_[np.ones((1, 3)), q[:1]],
                      objects=["brick-cube"], supports=["table"])
    write_scenes(scenes, tmp / "scenes.zarr")
    b = 3
    prior = PriorGrasps(object="brick-cube", pose=np.ones((b, 51), np.float32), contact_idx=np.ones((b, 4), np.int32),
                        plane=np.zeros((b, 4), np.float32), energies={k: np.ones(b) for k in ENERGY_TERMS},
                        pv=np.full(b, 1e-6), sd=np.full(b, 0.01), contact_distance=np.full(b, 0.001),
                        flags={"pv": np.ones(b, bool), "passed": np.ones(b, bool)})
    write_prior_grasps(prior, tmp / "prior.zarr")
    shutil.copytree(src / "task" / "brick-cube.zarr", tmp / "task.zarr")
    shutil.copytree(src / "shard-0.zarr", tmp / "shard.zarr")
    arrays = {"object_id": np.zeros(2, np.int32), "config_index": np.arange(2, dtype=np.int32),
              "contact": np.full((2, 2, 8), 0.5, np.float32), "grasp_init": np.ones((2, 2, 51), np.float32),
              "grasp_goal": np.ones((2, 2, 51), np.float32), "kept": np.ones((2, 2), bool)}
    write_predictions(arrays, {"task": "placing", "method": "ours", "objects": ["brick-cube"]}, tmp / "pred.zarr")
    return {"scenes": (tmp / "scenes.zarr", "target_init_pose", read_scenes),
            "prior grasps": (tmp / "prior.zarr", "pose", lambda p: read_prior_grasps(p, filtered=True)),
            "task grasps": (tmp / "task.zarr", "grasp_init", read_task_grasps),
            "map shard": (tmp / "shard.zarr", "contact", read_map_shard),
            "predictions": (tmp / "pred.zarr", "grasp_init", read_predictions)}


def _chunk_files(array_dir: Path) -> list[Path]:
    return sorted(f for f in (array_dir / "c").rglob("*") if f.is_file())


@pytest.mark.parametrize("damage", ["deleted chunk", "emptied file"])
def test_a_store_with_a_missing_or_emptied_chunk_is_refused_by_name(built, tmp_path, damage):  # noqa: F811
    for kind, (path, array, read) in _stores(built, tmp_path).items():
        read(path)  # intact: reads
        chunks = _chunk_files(path / array)
        assert chunks, f"{kind}: no chunk file under {path / array}"
        if damage == "deleted chunk":
            chunks[0].unlink()
        else:
            chunks[0].write_bytes(b"")
        with pytest.raises(ValueError, match=rf"{path.name}: array '{array}' (does not match its manifest|is unreadable)"):
            read(path)


@pytest.mark.parametrize("array", ["grasp_init", "grasp_goal"])
def test_a_prediction_store_with_non_finite_grasps_is_refused_by_name(tmp_path, array):
    """NaN goal grasps once passed (only the initial ones were checked) and scored goal OPP 0."""
    arrays = {"object_id": np.zeros(1, np.int32), "config_index": np.zeros(1, np.int32),
              "contact": np.full((1, 2, 8), 0.5, np.float32), "grasp_init": np.ones((1, 2, 51), np.float32),
              "grasp_goal": np.ones((1, 2, 51), np.float32), "kept": np.ones((1, 2), bool)}
    attrs = {"task": "placing", "method": "ours", "objects": ["brick-cube"]}
    write_predictions(arrays, attrs, tmp_path / "ok.zarr")  # finite: written
    arrays[array][0, 1, 3] = np.nan
    with pytest.raises(ValueError, match=rf"non-finite grasps in '{array}'"):
        write_predictions(arrays, attrs, tmp_path / "bad.zarr")


def test_a_store_without_a_manifest_is_refused(built, tmp_path):  # noqa: F811
    import zarr

    path, _, read = _stores(built, tmp_path)["map shard"]
    root = zarr.open_group(str(path), mode="a")
    del root.attrs["manifest"]
    with pytest.raises(ValueError, match=r"shard.zarr: no manifest of its arrays"):
        read(path)


# ---------------------------------------------------------------------------------------------------------
# A truncated mesh file is a rejection with its reason in the catalog, never a crash.

# Cut points of pybullet_data meshes, mid-way through a vertex line, that raised from trimesh (ValueError
# "Triangles must be (n, 3, 3)!", OverflowError) instead of being rejected.
TRUNCATED = [("teddy2_VHACD_CHs.obj", 56035), ("teddy2_VHACD_CHs.obj", 42630), ("random_urdfs/000/000.obj", 9173)]


def test_truncated_meshes_are_rejected_with_a_reason_and_the_catalog_builds(tmp_path):
    size = {"longest_min": 0.08, "longest_max": 0.16, "thickness_min": 0.012, "thickness_max": 0.08}
    dirs = []
    for k, (rel, cut) in enumerate(TRUNCATED):
        src = tmp_path / f"cut{k}.obj"
        src.write_bytes((pybullet_data_root() / rel).read_bytes()[:cut])
        spec = ObjectSpec(f"dir-cut{k}", "dir", "placing/shelving", str(src))
        meta = prepare_object(spec, tmp_path / "objects" / spec.name, size, 1.0, {}, 500.0, 0, None)
        assert meta["status"] == "rejected" and meta["reason"], meta
        dirs.append(tmp_path / "objects" / spec.name)
    cat = write_catalog(dirs, {"objects": {"test": 0.2, "val": 0.0}, "bricks": {"test": 0.2, "val": 0.0}}, 0,
                        tmp_path / "catalog.csv")
    assert (cat.status == "rejected").all() and (cat.reason.str.len() > 0).all()


# ---------------------------------------------------------------------------------------------------------
# Splits that cannot train or test are refused before any job; a training split without grasps names counts.


def test_a_split_without_test_or_training_objects_is_refused():
    split = {"objects": {"test": 0.0, "val": 0.0}, "bricks": {"test": 0.25, "val": 0.0}}
    with pytest.raises(ValueError, match=r"objects\.split\.objects: 3 selected placing/shelving objects give 3 "
                                         r"training and 0 test objects .* at least one test object"):
        check_split_sizes({"placing/shelving": 3, "stacking": 4}, split, ["placing/shelving", "stacking"])
    check_split_sizes({"placing/shelving": 3, "stacking": 4}, split, ["stacking"])  # placing not run: fine
    with pytest.raises(ValueError, match=r"objects\.split\.bricks: 1 selected stacking objects give 1 training "
                                         r"and 0 test"):
        check_split_sizes({"stacking": 1}, split, ["stacking"])


def test_an_empty_test_split_stops_snakemake_before_any_job(tmp_path):
    for d in ("workflow", "config", "tohgs", ".test", "profiles"):
        shutil.copytree(REPO / d, tmp_path / d, ignore=shutil.ignore_patterns("__pycache__"))
    cfg = yaml.safe_load((tmp_path / ".test/config/config.yaml").read_text())
    cfg["objects"]["split"]["objects"] = {"test": 0.0, "val": 0.0}
    (tmp_path / "no-test.yaml").write_text(yaml.safe_dump(cfg))
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--configfile", "no-test.yaml"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.returncode != 0
    assert "invalid configuration: objects.split.objects" in out.stdout + out.stderr
    assert not (tmp_path / "results").exists()


def test_a_training_split_without_task_grasps_names_the_objects_and_counts(built, tmp_path):  # noqa: F811
    tmp, hand, _, kw, _ = built
    arrays, attrs = read_task_grasps(tmp / "task" / "brick-cube.zarr")
    none = {k: (v[:0] if k != "kept_per_config" else np.zeros_like(v)) for k, v in arrays.items()}
    write_task_grasps(none, {**attrs, "n_prior_accepted": 5}, tmp_path / "brick-cube.zarr")
    with pytest.raises(EmptySplitError, match=r"placing/train: the split's 1 objects kept no task grasp.*brick-cube: "
                                              r"5 accepted prior grasps -> 0 task grasps over 2 configurations.*"
                                              r"scenes\.n_configs"):
        make_map_shard(**{**kw, "task_grasp_stores": [tmp_path / "brick-cube.zarr"]}, shard=0, out=tmp_path / "s.zarr")
    assert not (tmp_path / "s.zarr").exists()
    make_map_shard(**{**kw, "split": "test", "task_grasp_stores": [tmp_path / "brick-cube.zarr"]}, shard=0,
                   out=tmp_path / "t.zarr")  # a test split without grasps is no error (no Dataset row)


# ---------------------------------------------------------------------------------------------------------
# A resume file of other settings is not resumed.


def test_a_resume_file_of_other_settings_starts_afresh(built, tmp_path, monkeypatch, caplog):  # noqa: F811
    tmp, hand = built[0], built[1]
    shards = [tmp / "shard-0.zarr"]
    real = torch.nn.utils.clip_grad_norm_
    calls = {"n": 0}

    def crash(*a, **k):
        calls["n"] += 1
        if calls["n"] > 6:  # after the resume file of step 5
            raise KeyboardInterrupt("simulated kill")
        return real(*a, **k)

    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", crash)
    with pytest.raises(KeyboardInterrupt):
        train_component("contact_diffuser", "contact_diffuser", "placing", shards, TINY["contact_diffuser"], SETTINGS, tmp_path / "a.pt", hand=hand)
    assert (tmp_path / "a.pt.resume").is_file()
    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", real)
    changed = {**SETTINGS, "lr": 1e-3}
    with caplog.at_level("INFO"):
        resumed = train_component("contact_diffuser", "contact_diffuser", "placing", shards, TINY["contact_diffuser"], changed, tmp_path / "a.pt",
                              hand=hand)
    assert "written by a run with other settings or data" in caplog.text and "resuming" not in caplog.text
    straight = train_component("contact_diffuser", "contact_diffuser", "placing", shards, TINY["contact_diffuser"], changed, tmp_path / "b.pt",
                           hand=hand)
    for k, v in straight["state_dict"].items():
        torch.testing.assert_close(resumed["state_dict"][k], v, msg=k)
    assert resumed["training_config"]["lr"] == 1e-3


# ---------------------------------------------------------------------------------------------------------
# Smaller cases.


def test_an_inverted_range_is_a_config_error():
    with pytest.raises(ConfigError, match=r"'prior_grasps\.synthesis\.init_distance': \[min, max\] = \[0\.04, 0\.01\] "
                                          r"is not ordered"):
        validate_config({"prior_grasps": {"synthesis": {"init_distance": [0.04, 0.01]}}})


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_a_cuda_device_without_cuda_is_a_clear_error():
    with pytest.raises(ValueError, match=r"device 'cuda' was asked for, but .*set the device to 'auto'"):
        pick_device("cuda")
    assert pick_device("auto").type == "cpu"


def test_colliding_file_names_name_both_files_and_unusual_names_still_load(tmp_path):
    for name in ("cup-stl.obj", "cup.obj", "cup.stl"):  # cup.stl would be dir-cup-stl, as cup-stl.obj is
        (tmp_path / name).write_text("v 0 0 0\n")
    with pytest.raises(ValueError, match=r"the files 'cup-stl\.obj' and 'cup\.stl' .* both become the object name "
                                         r"'dir-cup-stl'"):
        dir_candidates(tmp_path)
    other = tmp_path / "other"
    other.mkdir()
    for name in ("日本.obj", "cup.obj", "cup.stl"):
        (other / name).write_text("v 0 0 0\n")
    specs = {Path(s.path).name: s.name for s in dir_candidates(other)}
    assert specs["cup.obj"] == "dir-cup" and specs["cup.stl"] == "dir-cup-stl"
    assert specs["日本.obj"].startswith("dir-u") and len(specs["日本.obj"]) == len("dir-u") + 8


def test_a_killed_writer_leaves_no_temporary_folder_for_good(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = socket.gethostname().replace(".", "_")
    target = tmp_path / "shard-0.zarr"
    stale = tmp_path / f".shard-0.zarr.{host}-{dead.pid}.x1y2.tmp"
    stale.mkdir()
    (stale / "zarr.json").write_text("{}")
    live = tmp_path / f".shard-0.zarr.{host}-{os.getpid()}.z9.tmp"  # a live writer's: kept
    live.mkdir()
    other = tmp_path / f".other.zarr.{host}-{dead.pid}.q.tmp"  # another output's: not this writer's business
    other.mkdir()
    with atomic_dir(target) as tmp:
        (tmp / "zarr.json").write_text("{}")
    assert target.is_dir() and not stale.exists() and live.exists() and other.exists()
    stale_file = tmp_path / f".table.csv.{host}-{dead.pid}.k.tmp"
    stale_file.write_text("half")
    with atomic_path(tmp_path / "table.csv") as tmp:
        tmp.write_text("done")
    assert not stale_file.exists() and (tmp_path / "table.csv").read_text() == "done"


# ---------------------------------------------------------------------------------------------------------
# What still got past (the issue "What still gets past"): config files read strictly, whole numbers that are
# floats, sizes beyond the machine's memory, a folder copied over another's, the kill window of a folder swap,
# damaged cache entries.


def test_a_repeated_config_key_is_refused_naming_the_file_and_both_lines(tmp_path):
    from tohgs.config_files import ConfigFileError, read_config_file

    path = tmp_path / "overlay.yaml"
    path.write_text("evaluation:\n  qr: {max_sd: 0.05}\n  qr:\n    max_pv: 1.0e-5\n")
    assert yaml.safe_load(path.read_text())["evaluation"]["qr"] == {"max_pv": 1.0e-5}  # what a plain load does
    with pytest.raises(ConfigFileError, match=rf"{path}: line 3: key 'qr' repeats the key of line 2"):
        read_config_file(path)
    (tmp_path / "o.json").write_text('{"seed": 1, "seed": 2}')
    with pytest.raises(ConfigFileError, match="key 'seed' repeats"):
        read_config_file(tmp_path / "o.json")
    (tmp_path / "merge.yaml").write_text("a: &a {x: 1, y: 2}\nb:\n  <<: *a\n  x: 3\n")  # a merge key overrides on purpose
    assert read_config_file(tmp_path / "merge.yaml")["b"] == {"x": 3, "y": 2}
    for shipped in [*(REPO / "config").glob("*.yaml"), REPO / ".test" / "config" / "config.yaml"]:
        read_config_file(shipped)


def test_the_workflow_reads_its_config_files_strictly(tmp_path):
    overlay = tmp_path / "overlay.yaml"
    overlay.write_text("seed: 3\nseed: 4\n")
    run = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--quiet", "rules", "--configfile", str(overlay),
                          "--cores", "1"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert run.returncode != 0
    assert f"invalid configuration: {overlay}: line 2: key 'seed' repeats the key of line 1" in run.stdout + run.stderr


def _laughs_of_mappings(levels: int, width: int = 9) -> str:
    lines = ["a0: &a0 {k: 1}"]
    lines += [f"a{i}: &a{i} {{" + ", ".join(f"k{j}: *a{i - 1}" for j in range(width)) + "}" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n"


def test_a_billion_laughs_of_mappings_is_refused_unexpanded(tmp_path):
    from tohgs.config_files import ConfigFileError, main, read_config_file

    path = tmp_path / "laughs.yaml"
    path.write_text(_laughs_of_mappings(9))  # 9^9 mappings once expanded: Snakemake's merge hangs on it
    t0 = time.perf_counter()
    with pytest.raises(ConfigFileError, match=rf"{path}: line \d+: the block here stands for more than 200000 values"):
        read_config_file(path)
    assert time.perf_counter() - t0 < 5.0
    (tmp_path / "loop.yaml").write_text("a: &a\n  - *a\n")
    with pytest.raises(ConfigFileError, match="recursive"):
        read_config_file(tmp_path / "loop.yaml")
    assert main([str(path)]) == 1  # python -m tohgs.config_files, which make reproduce CONFIG=... runs first
    assert main([str(REPO / "config" / "extras.yaml")]) == 0


@pytest.mark.parametrize(("patch", "key"), [
    ({"maps": {"shards": {"train": 1.0}}}, "maps.shards.train"),
    ({"prediction": {"samples": 2.0}}, "prediction.samples"),
    ({"seeds": [0, 1.0]}, "seeds.1"),
    ({"methods": {"ours": {"settings": {"samples": 4.0}}}}, "methods.ours.settings.samples"),
    ({"components": {"grasp_diffuser": {"training": {"steps": 100.0}}}}, "components.grasp_diffuser.training.steps"),
])
def test_a_whole_number_written_as_a_float_is_a_config_error_naming_its_key(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{re.escape(key)}': expected integer, got float .* \(write it "
                                          r"without a decimal point"):
        validate_config(patch)


def test_sizes_beyond_the_machine_memory_are_config_errors_that_say_what_fits():
    from tohgs.config import _memory_bounds, batch_bytes_per_sample

    with pytest.raises(ConfigError, match=r"config key 'prediction\.samples': 1000000000000 samples .* GiB .* more "
                                          r"than this machine's .* at most \d+ fit"):
        validate_config({"prediction": {"samples": 10**12}})
    with pytest.raises(ConfigError, match=r"config key 'methods\.ours\.settings\.samples'"):
        validate_config({"methods": {"ours": {"settings": {"samples": 10**12}}}})
    with pytest.raises(ConfigError, match=r"config key 'training\.batch'"):
        validate_config({"training": {"batch": 10**12}})
    cfg = validate_config({})
    per = batch_bytes_per_sample(cfg["maps"]["points"]["n_points"], cfg["maps"]["points"]["n_scene_points"])
    memory = per * cfg["prediction"]["chunk"] * 100  # room for 100 samples per configuration
    cfg["prediction"]["samples"] = 100
    _memory_bounds(cfg, memory)
    cfg["prediction"]["samples"] = 101
    with pytest.raises(ConfigError, match=r"at most 100 fit"):
        _memory_bounds(cfg, memory)


def test_an_object_folder_copied_over_another_is_an_error_naming_both(tmp_path):
    from tohgs.assets.manifest import check_object_file, record_object_files
    from tohgs.assets.sources import read_object_meta

    a = tmp_path / "objects" / "dir-a"
    a.mkdir(parents=True)
    (a / "mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    record_object_files(a, {"name": "dir-a", "status": "ok"}, ["mesh.obj"])
    check_object_file(a / "mesh.obj")
    b = tmp_path / "objects" / "dir-b"
    shutil.copytree(a, b)  # cp -a results/objects/dir-a results/objects/dir-b: every checksum matches
    with pytest.raises(ValueError, match=r"meta\.json: records the object 'dir-a', but its folder is 'dir-b'"):
        check_object_file(b / "mesh.obj")
    with pytest.raises(ValueError, match="records the object 'dir-a'"):
        read_object_meta(b)
    assert read_object_meta(a)["name"] == "dir-a"


def test_a_writer_killed_between_the_renames_of_a_folder_swap_loses_nothing(tmp_path):
    from tohgs.io import remove_stale_temporaries

    target = tmp_path / "import"
    with atomic_dir(target) as tmp:
        (tmp / "data.txt").write_text("first import")
    code = ("import os, sys, tohgs.io\n"
            "def killed(*a):\n    os._exit(9)\n"  # kill -9 at the instant the new folder would be renamed into place
            "tohgs.io.os.replace = killed\n"
            f"with tohgs.io.atomic_dir({str(target)!r}) as tmp:\n    (tmp / 'data.txt').write_text('second import')\n")
    assert subprocess.run([sys.executable, "-c", code], cwd=REPO).returncode == 9
    copies = [p for p in tmp_path.iterdir() if (p / "data.txt").is_file()]
    assert any((p / "data.txt").read_text() == "first import" for p in copies)  # a complete copy kept aside
    remove_stale_temporaries(target)  # what the next writer of the folder does first
    assert (target / "data.txt").read_text() == "first import"
    with atomic_dir(target) as tmp:
        (tmp / "data.txt").write_text("third import")
    assert (target / "data.txt").read_text() == "third import"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["import"]


def test_a_damaged_cache_entry_is_recomputed_not_trusted(tmp_path, caplog):
    from tohgs.cache import load_or_compute

    calls = []

    def compute() -> np.ndarray:
        calls.append(1)
        return np.arange(1000, dtype=np.float64)

    def get() -> tuple[np.ndarray, bool]:
        return load_or_compute(tmp_path, "voxels", "k" * 64, ".npy", compute,
                               lambda v, p: np.save(open(p, "wb"), v), lambda p: np.load(p, allow_pickle=False))

    value, hit = get()
    assert not hit and len(calls) == 1
    value, hit = get()
    assert hit and len(calls) == 1
    entry = tmp_path / "voxels" / f"{'k' * 64}.npy"
    data = bytearray(entry.read_bytes())
    data[-3] ^= 0x10  # a bit flip in the values: the file still loads
    entry.write_bytes(bytes(data))
    assert not np.array_equal(np.load(entry), np.arange(1000))
    with caplog.at_level("WARNING"):
        value, hit = get()
    assert not hit and len(calls) == 2 and np.array_equal(value, np.arange(1000))
    assert "do not match the SHA-256" in caplog.text
    (tmp_path / "voxels" / f"{'k' * 64}.npy.sha256").unlink()  # an entry without a checksum: not trusted either
    value, hit = get()
    assert not hit and len(calls) == 3
    assert get()[1]
