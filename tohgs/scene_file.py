"""A scene file: one's own configurations of a task for ``tohgs grasp --scene`` (YAML or JSON).

``tohgs grasp`` writes the configurations it used as ``scene.yaml`` in its output folder; edit it (move the
target, its goal, the obstacles) and pass it back with ``--scene``. The layout, every pose
``[x, y, z, qx, qy, qz, qw]`` (metres; scipy's xyzw quaternion) of an object's mesh frame in the support's
world frame, as the scene stores hold them (:mod:`tohgs.data.scenes`)::

    task: placing                  # placing, stacking or shelving: must be the --task
    configurations:
      - support: table             # a support of the run (results/objects/supports/supports.json)
        support_pose: [0, 0, 0, 0, 0, 0, 1]
        init: [0.1, -0.2, 0.04, 0, 0, 0, 1]      # the target where it is picked
        goal: [-0.3, 0.1, 0.04, 0, 0, 0, 1]      # and where it is put
        obstacles:                 # objects of the run by name (results/objects/<name>), at one pose each
          - {object: ycb-025-mug, pose: [0.2, -0.2, 0.05, 0, 0, 0, 1]}
        base: {object: brick-cube, pose: [...]}  # Stacking: the brick the target is put on

The target is the mesh ``tohgs grasp`` prepares (rescaled into the run's size range: its ``summary.json``
gives the extents), so poses are of that object. Poses are taken as given (nothing is settled by physics);
each configuration is checked: the target, at either pose, must not reach into the support, an obstacle
or the base by more than ``max_penetration``, nor an obstacle into the support.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: How far (metres) two bodies of a configuration may reach into each other (PyBullet's collision shapes:
#: convex parts touch at a few tenths of a millimetre).
MAX_PENETRATION = 0.002


class SceneFileError(ValueError):
    """A scene file that cannot be used: the message names the file, the configuration and the fix."""


def scene_document(scenes) -> dict[str, Any]:
    """The scene file's mapping of a :class:`tohgs.data.scenes.SceneSet` (module docstring)."""
    configs = []
    for c in range(len(scenes)):
        support, support_pose = scenes.support(c)
        entry: dict[str, Any] = {"support": support, "support_pose": _floats(support_pose),
                                 "init": _floats(scenes.target_init_pose[c]), "goal": _floats(scenes.target_goal_pose[c]),
                                 "obstacles": [{"object": o, "pose": _floats(p)} for o, p in scenes.obstacles(c)]}
        base = scenes.base(c)
        if base is not None:
            entry["base"] = {"object": base[0], "pose": _floats(base[1])}
        configs.append(entry)
    return {"task": scenes.task, "object": scenes.object, "configurations": configs}


def _floats(pose: np.ndarray) -> list[float]:
    return [round(float(v), 6) for v in pose]


def write_scene_file(scenes, path: str | Path) -> None:
    """Write ``scenes`` as a scene file (YAML), atomically."""
    import yaml

    from tohgs.io import atomic_path

    with atomic_path(path) as tmp:
        Path(tmp).write_text(yaml.safe_dump(scene_document(scenes), sort_keys=False, default_flow_style=None))


def _pose(value: Any, where: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64) if isinstance(value, (list, tuple)) else None
    if arr is None or arr.shape != (7,) or not np.all(np.isfinite(arr)):
        raise SceneFileError(f"{where}: a pose is 7 numbers [x, y, z, qx, qy, qz, qw], got {value!r}")
    norm = np.linalg.norm(arr[3:])
    if not 0.9 < norm < 1.1:
        raise SceneFileError(f"{where}: the quaternion {arr[3:].tolist()} is not of unit length ({norm:.3g})")
    arr[3:] /= norm
    return arr


def read_scene_file(path: str | Path, task: str, target: str, objects_dir: str | Path, supports_json: str | Path,
                    max_penetration: float = MAX_PENETRATION):
    """The :class:`tohgs.data.scenes.SceneSet` of a scene file for ``target`` (an object folder in
    ``objects_dir``), checked (module docstring).

    Raises:
        SceneFileError: unreadable, another task, an unknown support or object, a bad pose, a Stacking
            configuration without a base, or bodies that reach into each other (the message names the
            configuration, the bodies and by how much).
    """
    from tohgs.assets.supports import read_supports
    from tohgs.config_files import ConfigFileError, read_config_file
    from tohgs.data.scenes import SceneSet

    path = Path(path)
    try:
        doc = read_config_file(path)
    except (ConfigFileError, OSError) as err:
        raise SceneFileError(f"{path}: {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("configurations"), list) or not doc["configurations"]:
        raise SceneFileError(f"{path}: a scene file is a mapping with a non-empty list 'configurations' "
                             "(tohgs grasp writes one as scene.yaml in its output folder)")
    if doc.get("task", task) != task:
        raise SceneFileError(f"{path}: configurations of task {doc['task']!r}, but --task is {task!r}")
    supports = read_supports(supports_json)
    objects_dir = Path(objects_dir)
    names: list[str] = [target]
    rows: dict[str, list] = {k: [] for k in ("init", "goal", "support", "support_pose", "base", "base_pose")}
    obstacles: list[tuple[int, np.ndarray]] = []
    offsets = [0]
    known = {"support", "support_pose", "init", "goal", "obstacles", "base"}
    for c, entry in enumerate(doc["configurations"]):
        where = f"{path}: configurations[{c}]"
        if not isinstance(entry, dict):
            raise SceneFileError(f"{where}: a mapping with support, init, goal (and obstacles, base)")
        unknown = sorted(set(entry) - known)
        if unknown:
            raise SceneFileError(f"{where}: unknown keys {unknown} (known: {sorted(known)})")
        for key in ("support", "init", "goal"):
            if key not in entry:
                raise SceneFileError(f"{where}: '{key}' missing")
        if entry["support"] not in supports:
            raise SceneFileError(f"{where}: support {entry['support']!r} is not one of the run's "
                                 f"({', '.join(sorted(supports))})")
        rows["support"].append(sorted(supports).index(entry["support"]))
        rows["support_pose"].append(_pose(entry.get("support_pose", [0, 0, 0, 0, 0, 0, 1]), f"{where}.support_pose"))
        rows["init"].append(_pose(entry["init"], f"{where}.init"))
        rows["goal"].append(_pose(entry["goal"], f"{where}.goal"))
        base = entry.get("base")
        if (task == "stacking") != (base is not None):
            raise SceneFileError(f"{where}: " + ("Stacking puts the target on a base: give 'base: {object: brick-..., "
                                                 "pose: [...]}'" if base is None else f"a base is for Stacking, not {task}"))
        if base is not None:
            rows["base"].append(_object_index(base, names, objects_dir, f"{where}.base"))
            rows["base_pose"].append(_pose(base.get("pose"), f"{where}.base.pose"))
        else:
            rows["base"].append(-1)
            rows["base_pose"].append(np.full(7, np.nan))
        for k, ob in enumerate(entry.get("obstacles") or []):
            obstacles.append((_object_index(ob, names, objects_dir, f"{where}.obstacles[{k}]"),
                              _pose(ob.get("pose") if isinstance(ob, dict) else None, f"{where}.obstacles[{k}].pose")))
        offsets.append(len(obstacles))
    scenes = SceneSet(
        task=task, object=target,
        target_init_pose=np.array(rows["init"]), target_goal_pose=np.array(rows["goal"]),
        support_id=np.array(rows["support"], dtype=np.int32), support_pose=np.array(rows["support_pose"]),
        base_id=np.array(rows["base"], dtype=np.int32), base_pose=np.array(rows["base_pose"]),
        obstacle_offsets=np.array(offsets, dtype=np.int64),
        obstacle_id=np.array([i for i, _ in obstacles], dtype=np.int32).reshape(-1),
        obstacle_pose=np.array([p for _, p in obstacles], dtype=np.float64).reshape(-1, 7),
        objects=names, supports=sorted(supports), attrs={"scene_file": str(path.resolve())})
    scenes.validate(str(path))
    check_configurations(scenes, objects_dir, supports, max_penetration, str(path))
    return scenes


def _object_index(entry: Any, names: list[str], objects_dir: Path, where: str) -> int:
    from tohgs.assets.sources import read_object_meta

    name = entry.get("object") if isinstance(entry, dict) else None
    if not isinstance(name, str) or not (objects_dir / name / "object.urdf").is_file():
        available = sorted(p.name for p in objects_dir.iterdir() if (p / "object.urdf").is_file())
        raise SceneFileError(f"{where}: object {name!r} is not an accepted object of the run (results/objects/; "
                             f"e.g. {', '.join(available[:4])})")
    if read_object_meta(objects_dir / name)["status"] != "ok":
        raise SceneFileError(f"{where}: object {name!r} was rejected by the run's objects stage")
    if name == names[0]:
        raise SceneFileError(f"{where}: {name!r} is the target itself")
    if name not in names:
        names.append(name)
    return names.index(name)


def check_configurations(scenes, objects_dir: str | Path, supports: dict, max_penetration: float, source: str) -> None:
    """Every configuration's target at both poses clear of its support, obstacles and base, and every
    obstacle clear of the support, to within ``max_penetration`` metres (PyBullet's closest points of the
    collision shapes). Raises :class:`SceneFileError` naming the configuration, pose, bodies and depth."""
    import pybullet as pb

    from tohgs.sim.scenes import load_configuration
    from tohgs.sim.world import World

    with World() as world:
        for c in range(len(scenes)):
            for which in ("init", "goal"):
                bodies = load_configuration(world, scenes, c, objects_dir, supports, which=which, static=True)
                names = {"the target": [bodies["target"]], "the support": bodies["support"]}
                if bodies["base"] is not None:
                    names["the base"] = [bodies["base"]]
                for k, (oname, _) in enumerate(scenes.obstacles(c)):
                    names[f"obstacle {k} ({oname})"] = [bodies["obstacles"][k]]
                pairs = [("the target", other) for other in names if other != "the target"]
                pairs += [(o, "the support") for o in names if o.startswith("obstacle")] if which == "init" else []
                for a, b in pairs:
                    depth = max((-p[8] for ia in names[a] for ib in names[b]
                                 for p in pb.getClosestPoints(ia, ib, 0.0, physicsClientId=world.cid)), default=0.0)
                    if depth > max_penetration:
                        pose = "initial" if which == "init" else "goal"
                        raise SceneFileError(f"{source}: configurations[{c}]: at the {pose} pose {a} reaches "
                                             f"{depth * 1000:.1f} mm into {b} (at most {max_penetration * 1000:.0f} "
                                             "mm): move it")
