"""A prediction store's grasps out of the project: hand meshes (OBJ, PLY, GLB) and hand parameters (NPZ).

``python -m tohgs.export STORE --format obj|ply|glb|npz [--pose init|goal|both] [--out DIR]`` reads a
method's prediction store (``results/predictions/<task>/<method>.zarr``, :mod:`tohgs.data.predictions`;
docs/formats.md) with the run's hand (``results/hand/hand.npz``, found beside the store's ``results/``):

- a mesh format writes one file per grasp and pose, ``<object>_c<config>_s<sample>_<pose>.<ext>``: the hand
  posed by its 51-number grasp vector (:meth:`tohgs.hand.assets.HandAssets.vertices`), metres, world frame,
  the hand's faces (open at the wrist, as the model has them); kept and discarded grasps alike (the NPZ's
  ``kept`` says which). ``--with-scene`` (GLB only) puts the configuration in the same file: the target at
  that pose and the support, base brick and obstacles, each a named node (``hand``, ``target``,
  ``support:<name>``, ...), read from the run's ``results/`` as the viewer reads it
  (:class:`tohgs.viz.view_data.TaskResults`);
- ``npz`` writes one ``<task>_<method>.npz`` of every grasp's parameters in MANO's layout, each of shape
  (C, S, ...): ``transl`` (3, m), ``global_orient`` (3, axis-angle about the rest wrist joint, rad),
  ``hand_pose`` (45: 15 joints x axis-angle in MANO's joint order, relative to the flat hand: smplx's MANO
  with ``flat_hand_mean=True, use_pca=False``), ``betas`` (10, zeros: every grasp is of the mean shape), one
  set per pose (``init_`` and ``goal_`` prefixes), with ``object_id``, ``config_index``, ``kept``,
  ``objects``, ``hand`` (the backend's name: ``anny`` or ``mano``), and the hand's ``faces``. With the MANO
  backend the parameters are MANO's own; with anny they pose anny's hand, which has MANO's joints and layout
  (docs/hand.md). :func:`grasp_vectors` puts them back together.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.hand.layout import FINGER_POSE_DIM, GLOBAL_ROTATION_DIM, N_BETAS, TRANSLATION_DIM

log = logging.getLogger(__name__)

FORMATS = ("obj", "ply", "glb", "npz")
POSES = ("init", "goal")
#: The 51-number vector's parts, in its order: (name, width).
PARTS = (("transl", TRANSLATION_DIM), ("global_orient", GLOBAL_ROTATION_DIM), ("hand_pose", FINGER_POSE_DIM))


def split_grasps(grasps: np.ndarray) -> dict[str, np.ndarray]:
    """``(..., 51)`` grasp vectors as MANO's parameters: ``transl``, ``global_orient``, ``hand_pose`` and zero
    ``betas`` (float64)."""
    grasps = np.asarray(grasps, dtype=np.float64)
    if grasps.shape[-1] != sum(w for _, w in PARTS):
        raise ValueError(f"grasp vectors of {grasps.shape[-1]} numbers, not {sum(w for _, w in PARTS)}")
    out, start = {}, 0
    for name, width in PARTS:
        out[name] = grasps[..., start:start + width]
        start += width
    out["betas"] = np.zeros((*grasps.shape[:-1], N_BETAS))
    return out


def grasp_vectors(params: dict[str, np.ndarray], prefix: str = "") -> np.ndarray:
    """The ``(..., 51)`` grasp vectors of parameters written by :func:`export_npz` (``prefix``: ``"init_"`` or
    ``"goal_"``), the inverse of :func:`split_grasps`.

    Raises:
        ValueError: non-zero ``betas`` (the hand's vertices of a grasp are of the mean shape only).
    """
    betas = params.get(f"{prefix}betas")
    if betas is not None and np.any(np.asarray(betas) != 0):
        raise ValueError("non-zero betas: tohgs' grasps are of the mean hand shape")
    return np.concatenate([np.asarray(params[f"{prefix}{name}"], dtype=np.float64) for name, _ in PARTS], axis=-1)


def _hand_of(store: Path, hand: str | Path | None):
    from tohgs.hand import HandAssets

    path = Path(hand) if hand is not None else store.resolve().parent.parent.parent / "hand" / "hand.npz"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no hand file (the run's results/hand/hand.npz); pass --hand")
    return HandAssets.load(path)


def export_npz(store: str | Path, out: str | Path, hand: str | Path | None = None) -> Path:
    """Write the store's grasps as MANO-layout parameters (module docstring) to ``out`` (a folder: the file is
    ``<task>_<method>.npz`` in it), atomically; returns the file."""
    from tohgs.data.predictions import read_predictions
    from tohgs.io import atomic_path

    store = Path(store)
    arrays, attrs = read_predictions(store)
    assets = _hand_of(store, hand)
    fields: dict[str, Any] = {"object_id": arrays["object_id"], "config_index": arrays["config_index"],
                              "kept": arrays["kept"], "objects": np.asarray(attrs["objects"], dtype=str),
                              "hand": np.asarray(assets.name), "faces": np.asarray(assets.faces, dtype=np.int64)}
    for pose in POSES:
        for name, value in split_grasps(arrays[f"grasp_{pose}"]).items():
            fields[f"{pose}_{name}"] = value
    path = Path(out) / f"{attrs['task']}_{attrs['method']}.npz"
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **fields)
    return path


def export_meshes(store: str | Path, out: str | Path, fmt: str, poses: tuple[str, ...] = POSES,
                  hand: str | Path | None = None, with_scene: bool = False) -> list[Path]:
    """Write one hand mesh file per grasp and pose of the store (module docstring), each atomically; returns
    the files in the store's order (configuration, sample, pose). ``with_scene`` (GLB only): each file also
    holds the configuration's target at that pose and its scene."""
    import trimesh
    from tqdm import tqdm

    from tohgs.data.predictions import read_predictions
    from tohgs.io import atomic_path

    if fmt not in ("obj", "ply", "glb"):
        raise ValueError(f"format {fmt!r}: one of obj, ply, glb")
    if with_scene and fmt != "glb":
        raise ValueError(f"--with-scene needs --format glb (one file of several meshes), not {fmt}")
    store = Path(store)
    arrays, attrs = read_predictions(store)
    assets = _hand_of(store, hand)
    objects = attrs["objects"]
    scene_of = None
    if with_scene:
        from tohgs.viz.view_data import TaskResults

        scene_of = TaskResults.from_results(store.resolve().parent.parent.parent, attrs["task"], hand=assets)
    files = []
    n_configs = len(arrays["object_id"])
    for c in tqdm(range(n_configs), desc=f"export {store.name}", disable=n_configs < 8):
        name = f"{objects[int(arrays['object_id'][c])]}_c{int(arrays['config_index'][c])}"
        for pose in poses:
            verts = assets.vertices(np.asarray(arrays[f"grasp_{pose}"][c], dtype=np.float64))
            context = {}
            if scene_of is not None:
                obj, ci = objects[int(arrays["object_id"][c])], int(arrays["config_index"][c])
                context = {"target": scene_of.target(obj, ci, pose)}
                context |= {f"{p.kind}:{p.name}": p.world() for p in scene_of.parts(obj, ci)}
            for s, v in enumerate(verts):
                path = Path(out) / f"{name}_s{s}_{pose}.{fmt}"
                mesh = trimesh.Trimesh(v, assets.faces, process=False)
                if context:
                    mesh = trimesh.Scene({"hand": mesh, **context})
                with atomic_path(path) as tmp:
                    data = mesh.export(file_type=fmt)
                    Path(tmp).write_bytes(data if isinstance(data, bytes) else data.encode())
                files.append(path)
    return files


def main(argv: list[str] | None = None) -> int:
    """``python -m tohgs.export STORE --format obj|ply|glb|npz [--pose init|goal|both] [--out DIR]``."""
    parser = argparse.ArgumentParser(prog="python -m tohgs.export", description=__doc__.split("\n")[0])
    parser.add_argument("store", help="a prediction store, results/predictions/<task>/<method>.zarr")
    parser.add_argument("--format", choices=FORMATS, required=True)
    parser.add_argument("--pose", choices=(*POSES, "both"), default="both", help="mesh formats: which pose")
    parser.add_argument("--out", default=None, help="output folder (default: export/<task>/<method>/ here)")
    parser.add_argument("--with-scene", action="store_true", help="glb: the target at the pose and its scene in "
                        "each file (reads the run's results/)")
    parser.add_argument("--hand", default=None, help="the run's hand file (default: results/hand/hand.npz beside "
                        "the store's results/)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    store = Path(args.store)
    try:
        out = Path(args.out) if args.out else Path("export") / store.parent.name / store.name.removesuffix(".zarr")
        if args.format == "npz":
            print(export_npz(store, out, args.hand))
        else:
            poses = POSES if args.pose == "both" else (args.pose,)
            files = export_meshes(store, out, args.format, poses, args.hand, args.with_scene)
            print(f"{len(files)} files in {out}")
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
