"""Scene files (tohgs.scene_file): one's own configurations for tohgs grasp --scene, written from a scene set
and read back to the same arrays; poses, objects, supports and tasks checked; bodies that reach into each
other refused with the configuration, the bodies and the depth."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from helpers import prepare_small_object
from tohgs.assets.sources import ObjectSpec
from tohgs.assets.supports import write_supports
from tohgs.scene_file import SceneFileError, read_scene_file, scene_document, write_scene_file

UP = [0.0, 0.0, 0.0, 1.0]
LIFT: dict[str, float] = {}  # object -> the height of its mesh frame when it rests on the table


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Two bricks (the target cube, an obstacle disc) and the table, as a run's objects folder."""
    root = tmp_path_factory.mktemp("scene") / "objects"
    for name in ("cube", "disc"):
        spec = ObjectSpec(f"brick-{name}", "bricks", "stacking", None, name)
        meta = prepare_small_object(spec, root / spec.name, None)
        assert meta["status"] == "ok"
        LIFT[spec.name] = 0.0005 - meta["bounds"][0][2]  # its lowest point half a millimetre above the table
    write_supports([1.5, 1.0, 0.05], [], root / "supports")
    return root


def _doc(obstacle_xy=(0.2, 0.0), **change):
    lift = LIFT["brick-cube"]
    entry = {"support": "table", "init": [0.0, 0.0, lift, *UP], "goal": [-0.3, 0.2, lift, *UP],
             "obstacles": [{"object": "brick-disc", "pose": [*obstacle_xy, LIFT["brick-disc"], *UP]}]} | change
    return {"task": "placing", "configurations": [entry]}


def _read(run, tmp_path, doc, task="placing"):
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(doc))
    return read_scene_file(path, task, "brick-cube", run, run / "supports" / "supports.json")


def test_a_scene_file_round_trips(run, tmp_path):
    scenes = _read(run, tmp_path, _doc())
    assert len(scenes) == 1 and scenes.obstacles(0)[0][0] == "brick-disc" and scenes.support(0)[0] == "table"
    write_scene_file(scenes, tmp_path / "again.yaml")
    again = read_scene_file(tmp_path / "again.yaml", "placing", "brick-cube", run, run / "supports" / "supports.json")
    for name in ("target_init_pose", "target_goal_pose", "support_pose", "obstacle_pose"):
        assert np.abs(getattr(again, name) - getattr(scenes, name)).max() < 1e-6, name
    assert scene_document(again)["configurations"][0]["obstacles"][0]["object"] == "brick-disc"


@pytest.mark.parametrize("change, message", [
    (dict(obstacle_xy=(0.01, 0.0)), r"configurations\[0\]: at the initial pose the target reaches .* mm into "
                                    r"obstacle 0 \(brick-disc\)"),
    (dict(goal="sunk 2 cm"), r"at the goal pose the target reaches 2\d\.\d mm into the support"),
    (dict(init=[0, 0, 0.1, 0, 0, 0]), r"configurations\[0\]\.init: a pose is 7 numbers"),
    (dict(init=[0, 0, 0.1, 0, 0, 0, 2.0]), r"not of unit length"),
    (dict(support="shelf-wide"), r"support 'shelf-wide' is not one of the run's \(table\)"),
    (dict(obstacles=[{"object": "brick-house", "pose": [0.2, 0, 0, *UP]}]), r"'brick-house' is not an accepted object"),
    (dict(obstacles=[{"object": "brick-cube", "pose": [0.2, 0, 0, *UP]}]), r"'brick-cube' is the target itself"),
    (dict(base={"object": "brick-disc", "pose": [0.2, 0, 0, *UP]}), r"a base is for Stacking, not placing"),
    (dict(colour="red"), r"unknown keys \['colour'\]"),
])
def test_a_bad_configuration_names_itself_and_the_fix(run, tmp_path, change, message):
    xy = change.pop("obstacle_xy", (0.2, 0.0))
    if change.get("goal") == "sunk 2 cm":
        change["goal"] = [-0.3, 0.2, LIFT["brick-cube"] - 0.02, *UP]
    with pytest.raises(SceneFileError, match=message):
        _read(run, tmp_path, _doc(xy, **change))


def test_the_task_and_stackings_base_are_checked(run, tmp_path):
    with pytest.raises(SceneFileError, match="configurations of task 'placing', but --task is 'shelving'"):
        _read(run, tmp_path, _doc(), task="shelving")
    doc = _doc()
    doc["task"] = "stacking"
    with pytest.raises(SceneFileError, match="Stacking puts the target on a base"):
        _read(run, tmp_path, doc, task="stacking")
    with pytest.raises(SceneFileError, match="non-empty list 'configurations'"):
        _read(run, tmp_path, {"task": "placing", "configurations": []})
