"""Shared fixtures: the repository root, config loading, the end-to-end smoke run and a tiny map dataset
(``built``). Their one home: no test module imports another's fixtures (shared helpers: tests/helpers.py)."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture()
def default_config() -> dict:
    """A fresh copy of the embedded default config (config/config.yaml), unvalidated."""
    with open(REPO / "config" / "config.yaml") as fh:
        return copy.deepcopy(yaml.safe_load(fh))


@pytest.fixture(scope="session")
def smoke_run(tmp_path_factory) -> Path:
    """A finished smoke run (``.test/config/config.yaml``) in a copy of the workflow: its folder, with
    ``results/`` and ``logs/``. Once per session: tests/test_viewer.py reads it, tests/test_workflow.py reads it
    and reruns parts of it."""
    from workflow_tools import copy_workflow, workflow_env

    work = copy_workflow(tmp_path_factory.mktemp("smoke"))
    cmd = [sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", ".test/config/config.yaml"]
    out = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=1800, env=workflow_env(work))
    assert out.returncode == 0, (out.stdout + out.stderr)[-5000:]
    return work


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A tiny dataset: the cube brick on the table, two configurations, a grasp from above (placing); once per
    module that uses it. Returns ``(folder, hand, map shard, make_map_shard's keywords, cube mesh)``: the folder
    holds ``objects/``, ``scenes/``, ``task/`` and ``shard-0.zarr``."""
    import numpy as np
    import torch

    from helpers import placing_scene
    from tohgs.assets.bricks import make_brick
    from tohgs.assets.manifest import record_object_files
    from tohgs.assets.supports import read_supports, write_supports
    from tohgs.data.build_maps import make_map_shard
    from tohgs.data.scenes import write_scenes
    from tohgs.data.task_grasps import write_task_grasps
    from tohgs.grasps.expand import ExpansionSettings, expand_configurations
    from tohgs.hand import load_hand

    tmp = tmp_path_factory.mktemp("maps")
    hand = load_hand("anny")
    cube = make_brick("cube")
    cube.apply_translation(-cube.center_mass)
    (tmp / "objects" / "brick-cube").mkdir(parents=True)
    cube.export(tmp / "objects" / "brick-cube" / "mesh.obj")
    record_object_files(tmp / "objects" / "brick-cube", {"name": "brick-cube"}, ["mesh.obj"])
    write_supports([1.5, 1.0, 0.05], [], tmp / "objects" / "supports")
    sc = placing_scene(None)
    two = type(sc)(**{**sc.__dict__})
    for name in ("target_init_pose", "target_goal_pose", "support_id", "support_pose", "base_id", "base_pose"):
        setattr(two, name, np.concatenate([getattr(sc, name)] * 2))
    two.target_goal_pose[1, :2] = [-0.2, 0.25]
    two.obstacle_offsets = np.array([0, 0, 0], np.int64)
    (tmp / "scenes").mkdir()
    write_scenes(two, tmp / "scenes" / "brick-cube.zarr")
    grasp = hand.preset("relaxed", 3).numpy().astype(np.float64)
    with torch.no_grad():
        v = hand(torch.as_tensor(grasp, dtype=torch.float32)).vertices.numpy()
    lowest = v[np.arange(3), v[:, :, 2].argmin(1)]  # (3, 3): put it 5 mm above the top face's centre
    grasp[:, :3] += np.array([0.0, 0.0, cube.vertices[:, 2].max() + 0.005]) - lowest
    grasp[:, 0] += [-0.01, 0.0, 0.01]
    out = expand_configurations(two, grasp, hand.assets, tmp / "objects", read_supports(tmp / "objects/supports/supports.json"),
                                ExpansionSettings())
    (tmp / "task").mkdir()
    write_task_grasps(out, {"task": "placing", "object": "brick-cube"}, tmp / "task" / "brick-cube.zarr")
    kw = dict(task="placing", split="train", n_shards=1, scene_stores=[tmp / "scenes" / "brick-cube.zarr"],
              task_grasp_stores=[tmp / "task" / "brick-cube.zarr"], objects_dir=tmp / "objects",
              supports_json=tmp / "objects/supports/supports.json", hand=hand.assets,
              settings={"n_points": 256, "n_scene_points": 600, "scene_radius": 0.15}, test_configs=10, seed=0)
    shard = make_map_shard(shard=0, out=tmp / "shard-0.zarr", **kw)
    return tmp, hand, shard, kw, cube
