"""Task scenes: every stored configuration satisfies its task's rule when re-simulated; determinism;
the store's validation; running out of tries; a simulator crash becomes a clear error."""

from __future__ import annotations

import ctypes
import shutil

import numpy as np
import pytest

from tohgs.assets.objects import prepare_object
from tohgs.assets.sources import ObjectSpec
from tohgs.assets.supports import build_supports
from tohgs.config import validate_config
from tohgs.data.scenes import read_scenes, write_scenes
from tohgs.sim.isolation import SimulationCrash, run_isolated
from tohgs.sim.scenes import generate_scenes, load_configuration, load_object_asset, make_scene_store
from tohgs.sim.world import PhysicsSettings, World, quat_angle

CFG = validate_config({})
SCENES = CFG["scenes"]
PHYSICS = PhysicsSettings(**SCENES["physics"])
BRICKS = ("cube", "cuboid", "disc", "cylinder", "hexagonal-prism", "slab")


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    """A few prepared objects (convex bricks: no CoACD needed) and the supports."""
    root = tmp_path_factory.mktemp("objects")
    for b in BRICKS:
        prepare_object(ObjectSpec(f"brick-{b}", "bricks", "stacking", None, b), root / f"brick-{b}",
                       CFG["objects"]["size"], 1.0, CFG["objects"]["decomposition"], 500.0, 0, None)
    supports = {s.name: s for s in build_supports([1.5, 1.0, 0.05], CFG["objects"]["supports"]["shelves"][:1])}
    assets = [load_object_asset(root, f"brick-{b}") for b in BRICKS]
    return root, supports, assets


def _task_settings(task):
    return {**SCENES[task], "contact_margin": SCENES["contact_margin"]}


@pytest.fixture(scope="module")
def generated(library):
    root, supports, assets = library
    return {task: generate_scenes(task, assets[k], assets, supports, _task_settings(task), PHYSICS, 3, 40, False, 0)
            for k, task in enumerate(("placing", "stacking", "shelving"))}


def _displacement(a, b):
    return float(np.linalg.norm(a[:3] - b[:3])), quat_angle(a[3:], b[3:])


@pytest.mark.parametrize("task", ["placing", "shelving"])
def test_stored_configurations_are_valid_when_resimulated(library, generated, tmp_path, task):
    root, supports, _ = library
    write_scenes(generated[task], tmp_path / "s.zarr")
    scenes = read_scenes(tmp_path / "s.zarr")
    assert len(scenes) == 3
    with World(PHYSICS) as w:
        for c in range(len(scenes)):
            for which in ("init", "goal"):
                ids = load_configuration(w, scenes, c, root, supports, which=which)
                start = {b: w.pose(b) for b in [ids["target"], *ids["obstacles"]]}
                for ob in ids["obstacles"]:
                    assert not w.touching(ob, ids["target"], SCENES["contact_margin"]), (c, which)
                # 1 s of simulation: the target stays where it was stored (it had settled), every obstacle
                # stays on the support (an obstacle rebuilt from its pose may rock onto a neighbouring facet of
                # its convex hull, so it is not held to the target's tolerance) and none reaches the target.
                w.step(240)
                d, r = _displacement(w.pose(ids["target"]), start[ids["target"]])
                assert d < 0.005 and r < 0.1, (task, c, which, d, r)
                for ob in ids["obstacles"]:
                    assert abs(w.pose(ob)[2] - start[ob][2]) < 0.01, (task, c, which, "obstacle left the support")
                    assert not w.touching(ob, ids["target"], SCENES["contact_margin"] / 2), (c, which)
            assert np.linalg.norm(scenes.target_init_pose[c, :2] - scenes.target_goal_pose[c, :2]) >= \
                SCENES[task]["min_goal_distance"] - 1e-9


def test_stacking_configurations_are_stable_when_resimulated(library, generated, tmp_path):
    root, supports, _ = library
    write_scenes(generated["stacking"], tmp_path / "s.zarr")
    scenes = read_scenes(tmp_path / "s.zarr")
    s = SCENES["stacking"]
    with World(PHYSICS) as w:
        for c in range(len(scenes)):
            ids = load_configuration(w, scenes, c, root, supports, which="goal")
            base_name, base_pose = scenes.base(c)
            goal = scenes.target_goal_pose[c]
            assert goal[2] > base_pose[2], "the target is on top of the base"
            w.step(int(PHYSICS.settle_time / PHYSICS.time_step))
            for body, ref in ((ids["target"], goal), (ids["base"], base_pose)):
                d, r = _displacement(w.pose(body), ref)
                assert d < s["max_displacement"] and r < s["max_rotation"], (c, d, r)


def test_same_seed_same_store_and_another_seed_differs(library, generated, tmp_path):
    root, supports, assets = library
    again = generate_scenes("placing", assets[0], assets, supports, _task_settings("placing"), PHYSICS, 3, 40, False, 0)
    write_scenes(generated["placing"], tmp_path / "a.zarr")
    write_scenes(again, tmp_path / "b.zarr")
    a, b = read_scenes(tmp_path / "a.zarr"), read_scenes(tmp_path / "b.zarr")
    for name in ("target_init_pose", "target_goal_pose", "obstacle_offsets", "obstacle_id", "obstacle_pose"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    other = generate_scenes("placing", assets[0], assets, supports, _task_settings("placing"), PHYSICS, 3, 40, False, 1)
    assert not np.array_equal(other.target_init_pose, a.target_init_pose)


def test_reader_refuses_broken_stores(generated, tmp_path):
    write_scenes(generated["placing"], tmp_path / "ok.zarr")
    shutil.copytree(tmp_path / "ok.zarr", tmp_path / "trunc.zarr")
    shutil.rmtree(tmp_path / "trunc.zarr" / "obstacle_pose")
    with pytest.raises(ValueError, match="trunc.zarr: missing array 'obstacle_pose'"):
        read_scenes(tmp_path / "trunc.zarr")
    import zarr

    shutil.copytree(tmp_path / "ok.zarr", tmp_path / "old.zarr")
    zarr.open_group(str(tmp_path / "old.zarr"), mode="a").attrs["schema_version"] = 99
    with pytest.raises(ValueError, match="old.zarr: schema version 99"):
        read_scenes(tmp_path / "old.zarr")
    with pytest.raises(ValueError, match="nowhere.zarr: scene store not found"):
        read_scenes(tmp_path / "nowhere.zarr")


def test_running_out_of_tries_names_task_object_and_counts(library):
    root, supports, assets = library
    impossible = {**_task_settings("placing"), "min_goal_distance": 5.0}  # farther than the table allows
    with pytest.raises(RuntimeError, match=r"placing scenes for object 'brick-cube' \(seed 0\): only 0 valid .* "
                                           r"after 3 tries; rejections: no goal location far enough on the support: 3"):
        generate_scenes("placing", assets[0], assets, supports, impossible, PHYSICS, 2, 3, False, 0)
    fewer = generate_scenes("placing", assets[0], assets, supports, impossible, PHYSICS, 2, 3, True, 0)
    assert len(fewer) == 0 and fewer.attrs["tries"] == 3 and fewer.attrs["n_requested"] == 2


def _segfault() -> None:
    ctypes.string_at(0)  # reads address 0: SIGSEGV in the child


def test_a_simulator_crash_is_a_clear_error():
    with pytest.raises(SimulationCrash, match="while generating placing scenes for object 'x', seed 3"):
        run_isolated(_segfault, {}, "placing scenes for object 'x', seed 3")
    assert run_isolated(round, {"number": 2.567, "ndigits": 1}, "rounding") == 2.6


def test_make_scene_store_writes_an_attributed_store(library, tmp_path):
    root, supports, _ = library
    import json

    (root / "supports").mkdir(exist_ok=True)
    (root / "supports" / "supports.json").write_text(json.dumps({"supports": [s.to_dict() for s in supports.values()]}))
    settings = {**SCENES, "n_configs": 2}
    make_scene_store("stacking", "brick-cube", [f"brick-{b}" for b in BRICKS], root, root / "supports" / "supports.json",
                     settings, 0, tmp_path / "brick-cube.zarr")
    s = read_scenes(tmp_path / "brick-cube.zarr")
    assert len(s) == 2 and s.attrs["task"] == "stacking" and s.attrs["config"]["stacking"] == SCENES["stacking"]
    assert all(s.base(c) is not None for c in range(2))
    with pytest.raises(ValueError, match="not in the stacking pool"):
        make_scene_store("stacking", "brick-nope", ["brick-cube"], root, root / "supports" / "supports.json",
                         settings, 0, tmp_path / "x.zarr")
