"""The objects stage: turn one selected object into a normalised, simulation-ready asset, and the catalog.

Per object, :func:`prepare_object` writes ``results/objects/<name>/``:

- ``mesh.obj``: the normalised watertight mesh (metres, centre of mass at the origin, source orientation).
- ``collision.obj``: its convex decomposition, one ``o part_k`` group per convex part (PyBullet loads such a
  file as a compound of convex hulls).
- ``object.urdf``: a single-link URDF with ``mesh.obj`` as visual, ``collision.obj`` as collision and the
  mass properties at the configured density.
- ``meta.json``: the spec, status (``ok`` / ``rejected``), rejection reason, repairs, scale, extents,
  volume, mass and inertia, and under ``files`` the SHA-256, size and face count of the three files above,
  which every reader checks (:mod:`tohgs.assets.manifest`). A rejected object's folder holds only ``meta.json``.

:func:`write_catalog` gathers every ``meta.json`` into ``catalog.csv`` and assigns the train/val/test split
by object, per task set, deterministically for the seed.
"""

from __future__ import annotations

import logging
import time
import zlib
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import trimesh

from tohgs.assets.bricks import make_brick
from tohgs.assets.decomposition import DecompositionError, DecompositionSettings, convex_decomposition
from tohgs.assets.manifest import record_object_files
from tohgs.assets.mesh import (COLLISION_MESH, OBJECT_MESH, OBJECT_URDF, MeshError, MeshLimits, choose_scale,
                               load_mesh, mass_properties, normalise, repair_and_validate)
from tohgs.assets.sources import TASK_SET_BRICKS, TASK_SET_OBJECTS, ObjectSpec, read_object_meta
from tohgs.assets.splits import check_split_sizes, name_split, split_sizes
from tohgs.io import atomic_dir, atomic_path, write_json

log = logging.getLogger(__name__)

#: The files of an accepted object's folder that later stages read; ``meta.json`` records their checksums
#: (:mod:`tohgs.assets.manifest`).
OBJECT_FILES = (OBJECT_MESH, COLLISION_MESH, OBJECT_URDF)

CATALOG_COLUMNS = [
    "name", "source", "task_set", "split", "status", "reason", "scale", "extent_x", "extent_y", "extent_z",
    "volume", "mass", "watertight", "repairs", "n_collision_parts", "decomposition", "source_path",
]


def object_rng(seed: int, name: str) -> np.random.Generator:
    """The generator of one object's random choices: depends only on the seed and the object's name."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


def write_obj_parts(path: Path, parts: list[trimesh.Trimesh]) -> None:
    """Write convex parts as one OBJ file, one ``o part_<k>`` object each (the collision mesh's format)."""
    lines, offset = [], 1
    for k, p in enumerate(parts):
        lines.append(f"o part_{k}")
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in p.vertices]
        lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in p.faces]
        offset += len(p.vertices)
    path.write_text("\n".join(lines) + "\n")


def object_urdf(name: str, mass: float, inertia: np.ndarray) -> str:
    """The URDF text of an object folder: one link of ``mass`` (kg) and ``inertia`` (3, 3) about the centre of
    mass, visual ``mesh.obj``, collision ``collision.obj``."""
    i = inertia
    return f"""<?xml version="1.0"?>
<robot name="{name}">
  <link name="{name}">
    <inertial>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <mass value="{mass:.9g}"/>
      <inertia ixx="{i[0, 0]:.9g}" ixy="{i[0, 1]:.9g}" ixz="{i[0, 2]:.9g}" iyy="{i[1, 1]:.9g}" iyz="{i[1, 2]:.9g}" izz="{i[2, 2]:.9g}"/>
    </inertial>
    <visual><geometry><mesh filename="mesh.obj"/></geometry></visual>
    <collision><geometry><mesh filename="collision.obj"/></geometry></collision>
  </link>
</robot>
"""


def build_object_mesh(spec: ObjectSpec, size: dict[str, float], brick_scale: float, seed: int,
                      limits: MeshLimits | None = None) -> tuple[trimesh.Trimesh, float, list[str]]:
    """Load (or generate), repair, validate and normalise one object.

    Args:
        spec: the selected object.
        size: ``objects.size`` (longest_min/max, thickness_min/max, metres) for non-brick objects.
        brick_scale: uniform scale applied to the designed bricks.
        seed: global seed (the scale draw uses :func:`object_rng`).
        limits: the largest source file and face count, checked before the file is parsed (None: none).

    Returns:
        ``(mesh, scale, repairs)``: normalised mesh in metres, the scale applied to the source, repairs.

    Raises:
        MeshError: the object is unusable; the message is the rejection reason.
    """
    if spec.source == "bricks":
        raw = make_brick(spec.brick)
    else:
        raw = load_mesh(spec.path, limits)
    mesh, repairs = repair_and_validate(raw)
    if spec.source == "bricks":
        scale = float(brick_scale)
    else:
        scale = choose_scale(mesh.extents, (size["longest_min"], size["longest_max"]),
                             (size["thickness_min"], size["thickness_max"]), object_rng(seed, spec.name))
    mesh = normalise(mesh, scale)
    if not (mesh.is_watertight and mesh.volume > 0):
        raise MeshError("not watertight or non-positive volume after normalisation")
    return mesh, scale, repairs


def prepare_object(spec: dict[str, Any] | ObjectSpec, out_dir: str | Path, size: dict[str, float],
                   brick_scale: float, decomposition: dict[str, Any], density: float, seed: int,
                   cache_dir: str | Path | None, limits: dict[str, Any] | MeshLimits | None = None) -> dict[str, Any]:
    """Run the objects stage for one object and write its folder atomically.

    A bad mesh does not raise (whatever trimesh or the repair raise on it, or a crash of CoACD on it): the
    folder then holds a ``meta.json`` with ``status: rejected`` and the reason, so the rest of the run
    proceeds. So does a source file beyond ``limits`` (``objects.limits``; None: the defaults of
    :class:`MeshLimits`), refused before it is parsed.

    Returns:
        The metadata written to ``meta.json``.
    """
    spec = spec if isinstance(spec, ObjectSpec) else ObjectSpec(**spec)
    limits = limits if isinstance(limits, MeshLimits) else MeshLimits(**(limits or {}))
    t0 = time.perf_counter()
    meta: dict[str, Any] = {**spec.to_dict(), "status": "ok", "reason": ""}
    out_dir = Path(out_dir)
    with atomic_dir(out_dir) as tmp:

        def rejected(reason: str) -> dict[str, Any]:  # the folder holds only meta.json, with the reason
            meta.update(status="rejected", reason=reason)
            log.warning("%s rejected: %s", spec.name, reason)
            write_json(tmp / "meta.json", meta)
            return meta

        try:
            mesh, scale, repairs = build_object_mesh(spec, size, brick_scale, seed, limits)
        except Exception as exc:  # noqa: BLE001 - any failure on a bad file is a rejection, never a crash
            return rejected(str(exc) if isinstance(exc, MeshError) else f"invalid mesh ({type(exc).__name__}: {exc})")
        settings = DecompositionSettings(**decomposition)
        try:
            parts, method = convex_decomposition(mesh, settings, cache_dir)
        except DecompositionError as exc:  # CoACD aborted on this mesh: a rejection, not a failed run
            return rejected(f"convex decomposition failed: {exc}")
        mp = mass_properties(mesh, density)
        mesh.export(tmp / OBJECT_MESH)
        write_obj_parts(tmp / COLLISION_MESH, parts)
        (tmp / OBJECT_URDF).write_text(object_urdf(spec.name, mp.mass, mp.inertia))
        meta.update(
            scale=scale, extents=mesh.extents.tolist(), bounds=mesh.bounds.tolist(), volume=mp.volume,
            mass=mp.mass, density=density, inertia=mp.inertia.tolist(), watertight=bool(mesh.is_watertight),
            repairs=repairs, n_vertices=len(mesh.vertices), n_faces=len(mesh.faces),
            n_collision_parts=len(parts), decomposition=method,
            collision_volume=float(sum(p.volume for p in parts)),
        )
        record_object_files(tmp, meta, OBJECT_FILES)  # meta.json with the files' checksums, last
    log.info("%s: %s, scale %.4g, extents %s m, %d collision parts (%s), %.2f s", spec.name, meta["status"],
             scale, np.round(meta["extents"], 4).tolist(), len(parts), method, time.perf_counter() - t0)
    return meta


def assign_splits(names: list[str], test_fraction: float, val_fraction: float, rng: np.random.Generator
                  ) -> dict[str, str]:
    """Split object names into ``train``/``val``/``test`` (by object: no object is in two splits), with the
    sizes of :func:`split_sizes`."""
    _, n_val, n_test = split_sizes(len(names), test_fraction, val_fraction)
    order = rng.permutation(sorted(names))
    split = {str(nm): "test" for nm in order[:n_test]}
    split.update({str(nm): "val" for nm in order[n_test:n_test + n_val]})
    split.update({str(nm): "train" for nm in order[n_test + n_val:]})
    return split


def write_catalog(object_dirs: list[str | Path], split_cfg: dict[str, dict[str, float]], seed: int,
                  out_csv: str | Path, task_sets: list[str] | None = None,
                  skipped: list[tuple[str, str]] | None = None, dir_split: str | None = None) -> pd.DataFrame:
    """Gather the objects' ``meta.json`` into ``catalog.csv`` with the split by object: the embedded
    sources' accepted objects by a seeded draw among themselves (:func:`assign_splits`: exactly the sizes of
    the fractions), a user folder's (source ``dir``) each by its name (:func:`tohgs.assets.splits.name_split`)
    or all to ``dir_split``; so one's own objects never move an embedded object to another split.

    Args:
        object_dirs: the per-object folders of the objects stage.
        split_cfg: ``objects.split``: ``{"objects": {"test": f, "val": f}, "bricks": {...}}``.
        seed: global seed.
        out_csv: the catalog path.
        task_sets: the task sets the run's tasks use; each must keep a training and a test object after
            the rejections (None: no check).
        skipped: ``(file, reason)`` of the user folder's entries that never became objects
            (:func:`tohgs.assets.sources.dir_candidates`): rows of status ``skipped``, no name, the file in
            ``source_path``.
        dir_split: ``objects.sources.dir.split``: ``train``, ``val`` or ``test`` for every user-folder object,
            or None (each its own, by name).

    Returns:
        The catalog (one row per selected object and skipped file; rejected objects have split ``""``).

    Raises:
        ValueError: a task set without training or test objects (the message lists the rejections, or says
            how the user folder's objects were split).
    """
    rows = []
    for d in object_dirs:
        m = read_object_meta(d)
        ext = m.get("extents", [np.nan] * 3)
        rows.append({
            "name": m["name"], "source": m["source"], "task_set": m["task_set"], "split": "",
            "status": m["status"], "reason": m.get("reason", ""), "scale": m.get("scale", np.nan),
            "extent_x": ext[0], "extent_y": ext[1], "extent_z": ext[2], "volume": m.get("volume", np.nan),
            "mass": m.get("mass", np.nan), "watertight": m.get("watertight", False),
            "repairs": "; ".join(m.get("repairs", [])), "n_collision_parts": m.get("n_collision_parts", 0),
            "decomposition": m.get("decomposition", ""), "source_path": m.get("path") or "",
        })
    for file, reason in skipped or []:
        rows.append({"name": "", "source": "dir", "task_set": TASK_SET_OBJECTS, "split": "", "status": "skipped",
                     "reason": reason, "n_collision_parts": 0, "watertight": False, "source_path": file})
    df = pd.DataFrame(rows, columns=CATALOG_COLUMNS)
    if task_sets:
        ok = df[df.status == "ok"]
        rejected = "; ".join(f"{r['name'] or r['source_path']} {r['status']}: {r['reason']}"
                             for _, r in df[df.status != "ok"].iterrows())
        check_split_sizes(ok.task_set.value_counts().to_dict(), split_cfg, task_sets, "accepted",
                          rejected or "no object was rejected")
    for k, (task_set, key) in enumerate([(TASK_SET_OBJECTS, "objects"), (TASK_SET_BRICKS, "bricks")]):
        accepted = df[(df.task_set == task_set) & (df.status == "ok")]
        ok = accepted[accepted.source != "dir"].name.tolist()
        frac = split_cfg[key]
        split = assign_splits(ok, frac["test"], frac["val"], np.random.default_rng([seed, 10 + k])) if ok else {}
        for name in accepted[accepted.source == "dir"].name:
            split[name] = dir_split or name_split(name, seed, frac["test"], frac["val"])
        df.loc[df.name.isin(split), "split"] = df.loc[df.name.isin(split), "name"].map(split)
        if task_sets and task_set in task_sets and split:
            got = Counter(split.values())
            if not got["train"] or not got["test"]:
                raise ValueError(
                    f"objects.split.{key}: the {len(split)} accepted {task_set} objects give {got['train']} training "
                    f"and {got['test']} test objects ({len(split) - len(ok)} of them from objects.sources.dir, "
                    f"split {'by name' if dir_split is None else 'all to ' + dir_split}); the tasks need at least "
                    "one of each: pin the folder's objects with objects.sources.dir.split, or add objects")
    df = df.sort_values(["task_set", "name"], kind="stable").reset_index(drop=True)
    with atomic_path(out_csv) as tmp:
        df.to_csv(tmp, index=False)
    n_ok = int((df.status == "ok").sum())
    n_skipped = int((df.status == "skipped").sum())
    log.info("catalog: %d objects, %d accepted, %d rejected, %d files skipped", len(df) - n_skipped, n_ok,
             len(df) - n_ok - n_skipped, n_skipped)
    for _, r in df[df.status != "ok"].iterrows():
        log.info("%s %s: %s", r["status"], r["name"] or r["source_path"], r["reason"])
    return df


def read_catalog(path: str | Path, status: str | None = "ok") -> pd.DataFrame:
    """Read ``catalog.csv``, checking its columns; by default only accepted objects.

    Raises:
        ValueError: a missing column (names the file and the columns).
    """
    df = pd.read_csv(path, keep_default_na=False, na_values=[""])
    missing = set(CATALOG_COLUMNS) - set(df.columns)
    if missing:
        raise ValueError(f"{path}: not a tohgs catalog, missing columns {sorted(missing)}")
    df["split"] = df["split"].fillna("")
    df["reason"] = df["reason"].fillna("")
    df["name"] = df["name"].fillna("")  # a skipped file's row has none
    return df if status is None else df[df.status == status].reset_index(drop=True)
