"""Object sources and the deterministic selection."""

from __future__ import annotations

import copy

import pytest

from tohgs.assets.sources import (TASK_SET_BRICKS, dir_candidates, pybullet_named_candidates,
                                  pybullet_random_candidates, select_objects)
from tohgs.config import validate_config


def _objects_cfg(**counts):
    cfg = validate_config({})
    o = copy.deepcopy(cfg["objects"])
    o["sources"]["pybullet_data"].update(random_urdfs=counts.get("random", 5), named=counts.get("named", 2))
    o["sources"]["bricks"]["count"] = counts.get("bricks", 3)
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
