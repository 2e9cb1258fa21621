"""Bad input that once got past without a word (the cases of the issue "What bad input still gets past"): damaged
object files, non-finite settings, reserved replica names, unsafe file names, oversized meshes, a checkpoint of
another task, store attributes outside the manifest, a YAML "billion laughs". Each is refused or skipped with a
message that names the file or the key. The official importer's cases are in ``tests/test_official.py``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from workflow_tools import copy_workflow, workflow_env
from tohgs.assets.sources import ObjectSpec
from tohgs.config import SEED_MAX, ConfigError, _finite_numbers, validate_config

# ---------------------------------------------------------------------------------------------------------
# Settings: non-finite numbers, seeds beyond int64, replica names, a YAML billion laughs.


@pytest.mark.parametrize(("patch", "key"), [
    ({"evaluation": {"qr": {"max_sd": float("nan")}}}, "evaluation.qr.max_sd"),
    ({"prior_grasps": {"filter": {"max_sd": float("nan")}}}, "prior_grasps.filter.max_sd"),
    ({"training": {"lr": float("nan")}}, "training.lr"),
    ({"objects": {"size": {"longest_min": float("nan")}}}, "objects.size.longest_min"),
    ({"evaluation": {"qr_grid": {"max_sd": [0.01, float("inf")]}}}, "evaluation.qr_grid.max_sd.1"),
    ({"components": {"grasp_diffuser": {"training": {"lr": float("-inf")}}}}, "components.grasp_diffuser.training.lr"),
])
def test_a_non_finite_number_is_a_config_error_naming_its_key(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{key}': (nan|inf|-inf) is not a finite number"):
        validate_config(patch)


def test_the_schema_may_allow_non_finite_numbers_below_a_marked_key():
    schema = {"type": "object", "properties": {"a": {"type": "number"}, "b": {"type": "number", "x-nonfinite": True}}}
    _finite_numbers({"a": 1.0, "b": float("inf")}, schema)
    with pytest.raises(ConfigError, match="config key 'a'"):
        _finite_numbers({"a": float("nan"), "b": 1.0}, schema)


@pytest.mark.parametrize(("patch", "key"), [
    ({"seed": 2**64}, "seed"),
    ({"seeds": [0, 2**63]}, "seeds.1"),
    ({"evaluation": {"robust_sd": {"seed": -1}}}, "evaluation.robust_sd.seed"),
    ({"seeds": [0, 2**62], "training": {"seed": 2**62}}, "training.seed"),
    ({"seeds": [0, 2**62], "methods": {"ours": {"settings": {"seed": 2**62}}}}, "methods.ours.settings.seed"),
])
def test_a_seed_beyond_the_signed_64_bit_range_is_a_config_error(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{key}'.*(out of range|beyond the largest seed)"):
        validate_config(patch)
    validate_config({"seed": SEED_MAX, "seeds": [0, 1], "training": {"seed": SEED_MAX - 1}})  # the bound itself


@pytest.mark.parametrize(("patch", "key"), [
    ({"methods": {"ours-seed1": {"label": "Mine", "kind": "reference"}}, "seeds": [0, 1]}, "methods.ours-seed1"),
    ({"components": {"grasp_diffuser-seed1": {"kind": "grasp_diffuser"}}}, "components.grasp_diffuser-seed1"),
])
def test_a_name_like_a_seed_replica_is_a_config_error_that_says_why(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{key}': names ending in '-seed<k>' are reserved for the seed "
                                          r"replicas .* rename it"):
        validate_config(patch)
    validate_config({"methods": {"ours-seedless": {"label": "Mine", "kind": "reference"}}})  # only -seed<digits>


def test_a_yaml_billion_laughs_is_refused_before_anything_iterates_over_it():
    levels = ["l0: &l0 [" + ", ".join(["ours"] * 10) + "]"]
    levels += [f"l{k}: &l{k} [" + ", ".join([f"*l{k - 1}"] * 10) + "]" for k in range(1, 7)]
    text = "anchors:\n" + "".join(f"  {line}\n" for line in levels) + "figures:\n  comparisons:\n    laugh: *l6\n"
    cfg = yaml.safe_load(text)  # aliases load as shared references: cheap
    del cfg["anchors"]
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=r"config key 'figures\.comparisons\.laugh': the configuration holds more "
                                          r"than 200000 values"):
        validate_config(cfg)
    assert time.perf_counter() - t0 < 5.0


# ---------------------------------------------------------------------------------------------------------
# Object files: every file a later stage reads from results/objects/<name>/ is checked against its checksum.


@pytest.fixture(scope="module")
def brick_folder(tmp_path_factory) -> Path:
    """The objects stage's folder of the cube brick (fast decomposition settings)."""
    from helpers import prepare_small_object

    out = tmp_path_factory.mktemp("objects")
    meta = prepare_small_object(ObjectSpec("brick-cube", "bricks", "stacking", None, "cube"), out / "brick-cube", None)
    assert meta["status"] == "ok"
    return out / "brick-cube"


def _copy_folder(src: Path, root: Path) -> Path:
    shutil.copytree(src, root / src.name)
    return root / src.name


def _cut_lines(path: Path, keep: float) -> None:
    """Cut a text file at a line boundary, keeping about ``keep`` of its faces (what a truncated copy leaves)."""
    lines = path.read_text().splitlines(keepends=True)
    faces = [i for i, line in enumerate(lines) if line.startswith("f ")]
    path.write_text("".join(lines[:faces[int(len(faces) * keep)]]))


def test_the_objects_stage_records_the_checksums_of_its_files(brick_folder):
    files = json.loads((brick_folder / "meta.json").read_text())["files"]
    assert sorted(files) == ["collision.obj", "mesh.obj", "object.urdf"]
    for name, record in files.items():
        assert record["sha256"] == hashlib.sha256((brick_folder / name).read_bytes()).hexdigest()
        assert record["bytes"] == (brick_folder / name).stat().st_size
    assert files["mesh.obj"]["faces"] == 12 and files["collision.obj"]["faces"] >= 12


def test_a_collision_file_cut_at_a_line_boundary_is_an_error_naming_it(brick_folder, tmp_path):
    from tohgs.assets.mesh import collision_mesh
    from tohgs.metrics.quality import DisplacementSimulator

    folder = _copy_folder(brick_folder, tmp_path)
    _cut_lines(folder / "collision.obj", 0.5)
    with pytest.raises(ValueError, match=rf"{re.escape(str(folder / 'collision.obj'))}: does not match the checksum"):
        DisplacementSimulator(folder / "collision.obj", np.zeros(3))
    with pytest.raises(ValueError, match=r"collision\.obj: does not match the checksum .* rerun the objects stage "
                                         r"for 'brick-cube'"):
        collision_mesh(folder.parent, "brick-cube")


def test_a_mesh_cut_to_part_of_its_faces_is_an_error_naming_it(brick_folder, tmp_path):
    from tohgs.assets.mesh import object_mesh

    folder = _copy_folder(brick_folder, tmp_path)
    assert len(object_mesh(folder.parent, "brick-cube").faces) == 12
    for keep in (0.9, 0.6):
        shutil.copyfile(brick_folder / "mesh.obj", folder / "mesh.obj")
        _cut_lines(folder / "mesh.obj", keep)
        with pytest.raises(ValueError, match=rf"{re.escape(str(folder / 'mesh.obj'))}: does not match the checksum"):
            object_mesh(folder.parent, "brick-cube")


def test_a_mesh_that_loads_with_fewer_faces_than_recorded_is_an_error(brick_folder, tmp_path):
    """The second line of defence: a file whose checksum holds but which loads with fewer faces than the
    stage recorded (here the record says 13 of the 12)."""
    from tohgs.assets.mesh import object_mesh

    folder = _copy_folder(brick_folder, tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta["files"]["mesh.obj"]["faces"] = 13
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"mesh\.obj: loads with 12 faces, its objects stage recorded 13"):
        object_mesh(folder.parent, "brick-cube")


def test_a_damaged_urdf_or_a_folder_without_checksums_stops_the_simulator(brick_folder, tmp_path):
    from tohgs.sim.world import World

    folder = _copy_folder(brick_folder, tmp_path)
    pose = np.r_[0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 1.0]
    world = World()
    try:
        world.add_object(folder / "object.urdf", pose)  # intact: loads
        text = (folder / "object.urdf").read_text()
        (folder / "object.urdf").write_text(text.replace('mass value="', 'mass value="1'))
        with pytest.raises(ValueError, match=r"object\.urdf: does not match the checksum"):
            world.add_object(folder / "object.urdf", pose)
        (folder / "object.urdf").write_text(text)
        _cut_lines(folder / "collision.obj", 0.5)
        with pytest.raises(ValueError, match=r"collision\.obj: does not match the checksum"):
            world.add_object(folder / "object.urdf", pose)
        shutil.copyfile(brick_folder / "collision.obj", folder / "collision.obj")
        meta = json.loads((folder / "meta.json").read_text())
        del meta["files"]
        (folder / "meta.json").write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=r"records no checksums of the folder's files \(a folder of an older tohgs\)"):
            world.add_object(folder / "object.urdf", pose)
    finally:
        world.close()


def test_a_file_is_hashed_once_per_process(brick_folder, tmp_path, monkeypatch):
    import tohgs.io
    from tohgs.assets import manifest

    folder = _copy_folder(brick_folder, tmp_path)
    calls = []
    real = tohgs.io.hashlib.sha256
    monkeypatch.setattr(tohgs.io.hashlib, "sha256", lambda *a: calls.append(1) or real(*a))
    for _ in range(3):
        manifest.check_object_file(folder / "mesh.obj")
    assert len(calls) == 1
    data = bytearray((folder / "mesh.obj").read_bytes())
    i = next(k for k, b in enumerate(data) if chr(b).isdigit())
    data[i] = ord("9") if data[i] != ord("9") else ord("8")  # same size, other bytes
    (folder / "mesh.obj").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="does not match"):
        manifest.check_object_file(folder / "mesh.obj")  # a changed file is hashed again
    assert len(calls) == 2


# ---------------------------------------------------------------------------------------------------------
# An oversized mesh is rejected before it is parsed; the rule's memory covers the limit.


def test_an_oversized_mesh_is_rejected_with_a_reason_before_it_is_parsed(tmp_path, monkeypatch):
    import trimesh

    from tohgs.assets import mesh as mesh_module
    from tohgs.assets.objects import prepare_object

    big = tmp_path / "big.obj"
    trimesh.creation.torus(0.05, 0.02, major_sections=40, minor_sections=25).export(big)  # 2000 faces
    parsed = []
    real = mesh_module.trimesh.load
    monkeypatch.setattr(mesh_module.trimesh, "load", lambda *a, **k: parsed.append(a) or real(*a, **k))
    spec = ObjectSpec("dir-big", "dir", "placing/shelving", str(big))
    size = validate_config({})["objects"]["size"]
    meta = prepare_object(spec, tmp_path / "objects" / "dir-big", size, 1.0, {}, 500.0, 0, None,
                          limits={"max_faces": 1999, "max_file_mb": 100.0})
    assert meta["status"] == "rejected" and not parsed
    assert meta["reason"] == (f"{big}: 2000 faces, more than objects.limits.max_faces = 1999 (not parsed: repairing and "
                              "decomposing it would need more memory than the rule asks for; decimate the mesh, or "
                              "raise the limit with resources.rules.prepare_object.mem_mb)")
    meta = prepare_object(spec, tmp_path / "objects" / "dir-big", size, 1.0, {}, 500.0, 0, None,
                          limits={"max_faces": 2000, "max_file_mb": 0.01})
    assert meta["status"] == "rejected" and not parsed
    assert meta["reason"].startswith(f"{big}: a file of ") and "larger than objects.limits.max_file_mb = 0.01 MB" in meta["reason"]


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".ply"])
def test_faces_are_counted_without_parsing_the_file(tmp_path, suffix):
    import trimesh

    from tohgs.assets.mesh import count_faces

    mesh = trimesh.creation.torus(0.05, 0.02, major_sections=12, minor_sections=10)  # 240 faces
    mesh.export(tmp_path / f"t{suffix}")
    assert count_faces(tmp_path / f"t{suffix}") == 240
    if suffix == ".stl":
        mesh.export(tmp_path / "ascii.stl", file_type="stl_ascii")
        assert count_faces(tmp_path / "ascii.stl") == 240
    if suffix == ".obj":  # a quad counts as the two triangles it becomes
        (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
        assert count_faces(tmp_path / "quad.obj") == 2


def test_the_memory_of_the_objects_rule_covers_the_face_limit():
    from tohgs.assets.memory import prepare_memory_mb

    cfg = validate_config({})
    assert prepare_memory_mb(cfg["objects"]["limits"]["max_faces"]) <= cfg["resources"]["rules"]["prepare_object"]["mem_mb"]
    with pytest.raises(ConfigError, match=r"config key 'resources\.rules\.prepare_object\.mem_mb': 1000 MB is less than "
                                          r"the 1625 MB a mesh of objects\.limits\.max_faces = 200000 faces may need"):
        validate_config({"objects": {"limits": {"max_faces": 200_000}}})
    validate_config({"objects": {"limits": {"max_faces": 200_000}},
                     "resources": {"rules": {"prepare_object": {"mem_mb": 1625, "runtime": 30}}}})


# ---------------------------------------------------------------------------------------------------------
# A user folder: unsafe file names and entries that are no files are skipped with their reason.


def _user_folder(folder: Path) -> Path:
    import trimesh

    folder.mkdir()
    box = trimesh.creation.box(extents=(0.05, 0.06, 0.07))
    for name in ("cup{1}.obj", "new\nline.obj", "plain.obj"):
        box.export(folder / name)
    with open(os.fsencode(folder) + b"/bad\xff.obj", "wb") as fh:
        fh.write((folder / "plain.obj").read_bytes())
    os.symlink(folder / "gone.obj", folder / "dangling.obj")
    os.mkfifo(folder / "fifo.stl")
    (folder / "folder.ply").mkdir()
    (folder / "readme.txt").write_text("not a mesh: ignored without a word")
    return folder


def test_unsafe_names_and_entries_that_are_no_files_are_skipped_with_their_reason(tmp_path):
    from tohgs.assets.sources import dir_candidates

    folder = _user_folder(tmp_path / "mine")
    skipped: list[tuple[str, str]] = []
    specs = dir_candidates(folder, skipped)
    assert [s.name for s in specs] == ["dir-plain"]
    reasons = {Path(f.strip("'")).name: why for f, why in skipped}
    assert reasons == {
        "bad\\udcff.obj": "the name is not valid UTF-8",
        "cup{1}.obj": "the name holds '{' or '}', which Snakemake reads as a wildcard in an input path; rename the file",
        "dangling.obj": f"a dangling symbolic link (to {str(folder / 'gone.obj')!r})",
        "fifo.stl": "a FIFO, not a mesh file",
        "folder.ply": "a folder, not a mesh file",
        "new\\nline.obj": "the name holds control characters"}
    os.symlink(folder / "cup{1}.obj", folder / "link.obj")  # a safe name whose target is not
    skipped.clear()
    assert [s.name for s in dir_candidates(folder, skipped)] == ["dir-plain"]
    assert any(f.endswith("link.obj") and "it resolves to" in why and "'{' or '}'" in why for f, why in skipped)
    with pytest.raises(ValueError, match=r"objects\.sources\.dir\.path: folder .*brace\{s\}.* cannot hold workflow "
                                         r"inputs: the name holds '\{' or '\}'"):
        (tmp_path / "brace{s}").mkdir()
        dir_candidates(tmp_path / "brace{s}")


def test_skipped_files_are_listed_in_the_catalog(brick_folder, tmp_path):
    from tohgs.assets.objects import read_catalog, write_catalog

    split = {"objects": {"test": 0.0, "val": 0.0}, "bricks": {"test": 0.0, "val": 0.0}}
    cat = write_catalog([brick_folder], split, 0, tmp_path / "catalog.csv",
                        skipped=[("mine/fifo.stl", "a FIFO, not a mesh file")])
    assert sorted(cat.status) == ["ok", "skipped"]
    back = read_catalog(tmp_path / "catalog.csv", status=None)
    row = back[back.status == "skipped"].iloc[0]
    assert row["name"] == "" and row.source_path == "mine/fifo.stl" and row.reason == "a FIFO, not a mesh file"
    assert read_catalog(tmp_path / "catalog.csv").name.tolist() == ["brick-cube"]


def test_a_file_named_with_braces_no_longer_stops_the_workflow(tmp_path):
    """``cup{1}.obj`` once stopped every command at parse time with a WildcardError naming neither the file nor
    the folder; now it is skipped with a line that names it, and the rest of the folder runs."""
    workdir = copy_workflow(tmp_path / "wf")
    _user_folder(workdir / "mine")
    (workdir / "dir.yaml").write_text(yaml.safe_dump({"objects": {"sources": {"dir": {"path": "mine"}}}}))
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--configfile",
                          ".test/config/config.yaml", "dir.yaml", "--until", "catalog"], cwd=workdir,
                         env=workflow_env(workdir), capture_output=True, text=True, timeout=600)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-3000:]
    assert "WildcardError" not in text and "results/objects/dir-plain" in text
    assert ("objects.sources.dir: skipped 'mine/cup{1}.obj': the name holds '{' or '}', which Snakemake reads as "
            "a wildcard in an input path; rename the file") in text
    assert "objects.sources.dir: skipped mine/fifo.stl: a FIFO, not a mesh file" in text


# ---------------------------------------------------------------------------------------------------------
# A checkpoint of another task or component; store attributes outside the manifest.


def _checkpoints(folder: Path, task: str) -> dict[str, Path]:
    """Untrained checkpoints of the tiny ContactDiffuser and GraspDiffuser of tests/test_train.py for ``task``."""
    from helpers import TINY
    from tohgs.models.checkpoint import save_checkpoint
    from tohgs.models.component import build_component

    folder.mkdir(exist_ok=True)
    paths = {}
    for name in ("contact_diffuser", "grasp_diffuser"):
        paths[name] = folder / f"{name}.pt"
        save_checkpoint(paths[name], build_component(name, TINY[name]), name, task, TINY[name], {}, loss_curve=[])
    return paths


def test_a_checkpoint_of_another_task_or_component_is_refused(tmp_path):
    from helpers import OURS
    from tohgs.methods.predict import predict
    from tohgs.models.checkpoint import load_component

    shelving = _checkpoints(tmp_path / "shelving", "shelving")
    settings = {"samples": 1, "device": "cpu"}
    with pytest.raises(ValueError, match=rf"{re.escape(str(shelving['contact_diffuser']))}: a checkpoint of task "
                                         r"'shelving', but this job needs task 'placing' \(a file copied into place\?"):
        predict("placing", "ours", OURS, [], shelving, settings, tmp_path / "p.zarr")
    placing = _checkpoints(tmp_path / "placing", "placing")
    shutil.copyfile(placing["grasp_diffuser"], placing["contact_diffuser"])  # the other component copied into place
    with pytest.raises(ValueError, match=r"contact_diffuser\.pt: a checkpoint of component 'grasp_diffuser', but this "
                                         r"job needs component 'contact_diffuser'"):
        predict("placing", "ours", OURS, [], placing, settings, tmp_path / "p.zarr")
    assert not (tmp_path / "p.zarr").exists()
    _, ckpt = load_component(shelving["grasp_diffuser"], task="shelving", component="grasp_diffuser")  # its own: fine
    assert ckpt["task"] == "shelving"


def test_store_root_attributes_are_in_the_manifest(tmp_path):
    from tohgs.data.store import MANIFEST, read_store, write_store

    path = tmp_path / "s.zarr"
    write_store(path, {"x": (np.arange(6.0).reshape(3, 2), ("row", "xy"))},
                {"objects": ["brick-a", "brick-b"], "alpha_contact": 100.0, "nested": {"k": [1, 2]}}, "test", 1)
    arrays, attrs = read_store(path, "test", 1, None, "test store")
    assert attrs["objects"] == ["brick-a", "brick-b"] and attrs["alpha_contact"] == 100.0
    meta_path = path / "zarr.json"
    original = json.loads(meta_path.read_text())
    for edit in ({"objects": ["brick-b", "brick-a"]}, {"alpha_contact": 50.0}, {"nested": {"k": [1, 3]}}):
        meta = json.loads(json.dumps(original))
        meta["attributes"].update(edit)
        meta_path.write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=rf"{re.escape(str(path))}: its root attributes \(zarr\.json\) do not match "
                                             r"their manifest checksum"):
            read_store(path, "test", 1, None, "test store")
    meta = json.loads(json.dumps(original))
    meta["attributes"][MANIFEST] = meta["attributes"][MANIFEST]["arrays"]  # an older tohgs's manifest
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"its manifest does not cover the root attributes \(a store of an older tohgs\)"):
        read_store(path, "test", 1, None, "test store")
