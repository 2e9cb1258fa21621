"""A small synthetic tree in the exact layout and formats of the official TOHGS dataset (meshes, lists,
pickled ``.npy`` grasp files, test JSONs; docs/official_dataset.md), with a few bad files, for the importer's
tests and the official workflow's. Nothing of the real dataset is used."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

DS = "task_oriented_grasps_dataset"
TABLE_TOP = 0.6 + 0.025  # a unit cube centred on the origin, scaled by 0.05 in z and put at z = 0.6


def _write_boxes(path: Path, boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]]) -> None:
    """An OBJ of axis-aligned boxes ``(centre, size)``, one ``o`` group each (CoACD's layout)."""
    import trimesh

    lines, offset = [], 1
    for k, (centre, size) in enumerate(boxes):
        m = trimesh.creation.box(extents=size)
        m.apply_translation(centre)
        lines.append(f"o convex_{k}")
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in m.vertices]
        lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in m.faces]
        offset += len(m.vertices)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def _pose(rng: np.random.Generator, z: float = TABLE_TOP + 0.05) -> np.ndarray:
    q = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi)).as_quat()
    return np.r_[rng.uniform(-0.4, 0.4, 2), z, q]


def _grasp(rng: np.random.Generator, near: np.ndarray) -> np.ndarray:
    g = np.r_[near[:3] + rng.normal(0, 0.05, 3), rng.normal(0, 0.8, 3), rng.normal(0, 0.2, 45)]
    return g.reshape(1, 51).astype(np.float32)


def _save_npy(path: Path, d: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, d, allow_pickle=True)  # what the official code reads with np.load(...).item()


def _write_json(path: Path, d: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(d))


def make_official_tree(root: Path) -> dict:
    """Write the official layout below ``root``: 2 Placing objects (one corrupt .npy besides), 1 Shelving
    object (one file with unequal list lengths besides), 3 Stacking bricks; meshes, lists, .npy grasp files
    and test JSONs. Returns ``{"root": root, "src": {"<task>/<stem>": the dict written}}``."""
    rng = np.random.default_rng(0)
    md = root / "models"
    # mug_a: two overlapping parts, off-centre in its own frame; can_b: one box raised 5 cm; box_c: obstacle.
    _write_boxes(md / "meshdata/mug_a/coacd/decomposed_scaled.obj",
                 [((0.01, -0.02, 0.03), (0.06, 0.04, 0.08)), ((0.06, -0.02, 0.03), (0.04, 0.03, 0.03))])
    _write_boxes(md / "meshdata/can_b/coacd/decomposed_scaled.obj", [((0.0, 0.0, 0.05), (0.05, 0.05, 0.1))])
    _write_boxes(md / "meshdata/box_c/coacd/decomposed_scaled.obj", [((0.0, 0.0, 0.0), (0.08, 0.08, 0.08))])
    for b in "ACF":
        _write_boxes(md / f"brick/{b}/textured_simple.obj", [((0.0, 0.0, 0.0), (0.03, 0.06, 0.03))])
    _write_boxes(md / "selected_shelf/shelf01/coacd/decomposed.obj",
                 [((0, 0, 0.01), (0.6, 0.3, 0.02)), ((-0.29, 0, 0.2), (0.02, 0.3, 0.4)),
                  ((0.29, 0, 0.2), (0.02, 0.3, 0.4)), ((0, 0, 0.39), (0.6, 0.3, 0.02))])
    _write_boxes(md / "table/table.obj", [((0, 0, 0), (1.0, 1.0, 1.0))])

    ds = root / DS
    src: dict = {}
    # Placing: mug_a rows 0 and 1 share their scene (one configuration, two grasps); can_b two scenes.
    scene = [_pose(rng), _pose(rng), [_pose(rng).tolist()], ["box_c"]]
    other = [_pose(rng), _pose(rng), [], []]
    rows = [scene, scene, other]
    src["placing/mug_a"] = {
        "init_pose": [r[0] for r in rows], "goal_pose": [r[1] for r in rows],
        "recon_param": [_grasp(rng, r[0]) for r in rows], "obstacle_pose": [r[2] for r in rows],
        "obstacle_name": [r[3] for r in rows]}
    src["placing/can_b"] = {
        "init_pose": [_pose(rng), _pose(rng)], "goal_pose": [_pose(rng), _pose(rng)],
        "recon_param": [_grasp(rng, np.zeros(3)), _grasp(rng, np.zeros(3))],
        "obstacle_pose": [[_pose(rng).tolist(), _pose(rng).tolist()], []], "obstacle_name": [["box_c", "mug_a"], []]}
    for key, d in src.items():
        _save_npy(ds / f"{key}.npy", d)
    (ds / "placing/broken.npy").write_bytes(b"\x93NUMPY\x01\x00v\x00{'descr': '|O', 'fortran_order': False, 'shap")
    (ds / "placing/train.txt").write_text("mug_a.npy\nbroken.npy\n")
    (ds / "placing/val.txt").write_text("can_b.npy\n")
    test = {"grasped_obj_name": "can_b", "init_pose": [_pose(rng).tolist() for _ in range(3)],
            "goal_pose": [_pose(rng).tolist() for _ in range(3)],
            "obstacle_name": [["box_c"], [], ["mug_a", "box_c"]],
            "obstacle_pose": [[_pose(rng).tolist()], [], [_pose(rng).tolist(), _pose(rng).tolist()]]}
    _write_json(ds / "placing/test/can_b.json", test)
    src["placing/test/can_b"] = test

    # Shelving: shelf_name as 0-d string arrays (their loader calls .item()); uneven.npy has unequal lists.
    shelf = np.r_[0.2, 0.1, TABLE_TOP, 0, 0, 0, 1.0]
    src["shelving/mug_a"] = {
        "init_pose": [_pose(rng, TABLE_TOP + 0.1) for _ in range(2)],
        "goal_pose": [_pose(rng, TABLE_TOP + 0.3) for _ in range(2)],
        "recon_param": [_grasp(rng, np.zeros(3)) for _ in range(2)], "obstacle_pose": [[_pose(rng).tolist()], []],
        "obstacle_name": [["can_b"], []], "shelf_pose": [shelf, shelf], "shelf_name": [np.array("shelf01")] * 2}
    _save_npy(ds / "shelving/mug_a.npy", src["shelving/mug_a"])
    _save_npy(ds / "shelving/uneven.npy", {**src["shelving/mug_a"], "goal_pose": [_pose(rng)]})
    (ds / "shelving/train.txt").write_text("uneven.npy\n")
    (ds / "shelving/val.txt").write_text("mug_a.npy\n")
    test = {"grasped_obj_name": ["mug_a", "mug_a"], "init_pose": [_pose(rng).tolist() for _ in range(2)],
            "goal_pose": [_pose(rng).tolist() for _ in range(2)], "obstacle_name": [[], ["box_c"]],
            "obstacle_pose": [[], [_pose(rng).tolist()]], "shelf_name": ["shelf01", "shelf01"],
            "shelf_pose": [shelf.tolist(), shelf.tolist()]}
    _write_json(ds / "shelving/test/mug_a.json", test)
    src["shelving/test/mug_a"] = test

    # Stacking: A and C train, F val (the hard-coded split); the key is recon_parms (sic).
    def stack(base: str, target: str) -> list:
        return [base, _pose(rng).tolist(), target, _pose(rng).tolist()]

    for brick, base, n in (("A", "C", 2), ("C", "A", 1), ("F", "A", 1)):
        init = [stack(base, brick) for _ in range(n)]
        goal = [[e[0], e[1], brick, _pose(rng, TABLE_TOP + 0.1).tolist()] for e in init]
        src[f"stacking/{brick}"] = {"init": init, "goal": goal,
                                    "recon_parms": [_grasp(rng, np.asarray(e[3])) for e in init]}
        _save_npy(ds / f"stacking/{brick}.npy", src[f"stacking/{brick}"])
    test = {"init": [stack("A", "F") for _ in range(2)]}
    test["goal"] = [[e[0], e[1], "F", _pose(rng, TABLE_TOP + 0.1).tolist()] for e in test["init"]]
    _write_json(ds / "stacking/test/F.json", test)
    src["stacking/test/F"] = test
    return {"root": root, "src": src}
