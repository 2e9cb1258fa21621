"""The importer of the official TOHGS dataset: the official tree (:mod:`tohgs.official.format`) into
tohgs's stores.

**What it writes** (below ``out``, the layout of ``results/``):

==========================================  ======================================================
``objects/<name>/``                         ``mesh.obj`` (watertight, centre of mass at the origin),
                                            ``collision.obj``, ``object.urdf``, ``meta.json``
``objects/catalog.csv``                     the catalog, with the official split
``objects/supports/``                       ``supports.json`` and ``<support>.obj``: the table, shelves
``scenes/<task>/<name>.zarr``               scene stores of the rows' configurations
``grasps/task/<task>/<name>.zarr``          task-grasp stores: the rows' grasps
``test_scenes/<task>/<name>.zarr``          scene stores of the test JSONs' configurations, in order
``checksums.sha256``                        SHA-256 of every file read (``sha256sum -c`` format)
``import_report.json``                      counts, the hand, the splits per task, every unusable file
==========================================  ======================================================

**Configurations.** The official dataset stores one grasp per row, each row with its own scene. Rows with
identical scenes (bit-identical init pose, goal pose, obstacles, shelf, base) are one configuration with
several grasps; other rows are a configuration each. This loses nothing (each grasp keeps its row, attrs
``official.row`` of the task-grasp store) and gives the stages what they expect from a task-grasp store:
the grasps of one scene side by side.

**Unreadable files** (a bad pickle, a refused pickle global, missing keys, unequal list lengths, bad
shapes, a position beyond :data:`~tohgs.official.format.POSITION_BOUND` of the origin, a missing listed
file, a mesh that fails validation or exceeds the mesh limits, an official name that becomes the same tohgs
name as another's, a grasp file listed in both ``train.txt`` and ``val.txt``) are counted and reported with
their reasons (:class:`ImportReport`, ``import_report.json``), never skipped silently and never a crash; files
are read safely (:mod:`tohgs.official.format`'s Reading). An import is written into a temporary folder and
renamed into place when complete.
"""

from __future__ import annotations

import hashlib
import json
import logging
import reprlib
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from tohgs.assets.decomposition import DecompositionSettings, cap_hull_vertices, convex_decomposition
from tohgs.assets.manifest import record_object_files
from tohgs.assets.mesh import (COLLISION_MESH, OBJECT_MESH, OBJECT_URDF, MeshError, MeshLimits, load_mesh,
                               mass_properties, repair_and_validate)
from tohgs.assets.objects import CATALOG_COLUMNS, OBJECT_FILES, object_urdf, write_obj_parts
from tohgs.assets.sources import TASK_SET_BRICKS, TASK_SET_OBJECTS
from tohgs.assets.supports import Box, Support, make_table
from tohgs.data.scenes import SceneSet, write_scenes
from tohgs.data.task_grasps import write_task_grasps
from tohgs.geometry.grasp import pose_matrix, transform_grasp
from tohgs.hand.assets import HandAssets
from tohgs.io import atomic_dir, atomic_path, write_json
from tohgs.official.format import (DATASET_DIR, NO_PRIOR, POSITION_BOUND, SPLIT_OF, STACKING_SPLIT, TABLE_HEIGHT,
                                   TABLE_SCALE, TASKS, Row, from_official_pose, load_official_npy, mesh_path,
                                   object_name, parse_rows, shelf_name, shelf_path, shift_grasp)

log = logging.getLogger(__name__)


# --- reading -------------------------------------------------------------------------------------------

class _Reader:
    """Reads files below ``root`` and keeps the SHA-256 of each one read (relative POSIX path -> hex)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.digests: dict[str, str] = {}

    def exists(self, rel: str) -> bool:
        return (self.root / rel).is_file()

    def read(self, rel: str) -> bytes:
        data = (self.root / rel).read_bytes()
        self.digests[rel] = hashlib.sha256(data).hexdigest()
        return data

    def hash(self, rel: str) -> Path:
        """Record the digest of a file another reader (trimesh) will parse; returns its path. The file is hashed
        a block at a time, never held whole: the reader's own limits (:func:`~tohgs.assets.mesh.load_mesh`'s
        file size) are what refuse a file too large."""
        path = self.root / rel
        with open(path, "rb") as fh:
            self.digests[rel] = hashlib.file_digest(fh, "sha256").hexdigest()
        return path



@dataclass
class ImportReport:
    """What an import read, wrote and could not use.

    Attributes:
        root, out: the official tree and the output folder.
        table_top: height of the official table's top, m (the z shift of every pose).
        files_read: files read (each has a line in ``checksums.sha256``).
        problems: per unreadable or missing file ``{"path", "kind", "reason"}``; ``kind`` is ``unreadable``
            (also absurd numbers: a position beyond :data:`POSITION_BOUND`, a wrong shape), ``missing``,
            ``mesh`` (a mesh that failed validation), ``name`` (an official name that becomes the same tohgs
            name as another's; both files named) or ``split`` (a grasp file listed in both ``train.txt`` and
            ``val.txt``, imported in neither split; the path is ``val.txt``, the reason names both lists).
        notes: what was read differently from the lists, or not at all (unlisted files), for the record.
        tasks: per task ``files``, ``rows`` (grasps), ``configurations``, ``test_files``,
            ``test_configurations``, ``targets``.
        objects: ``ok`` and ``rejected`` object counts.
        hand: the name of the hand whose rest wrist carried each grasp to its goal pose (``anny``, ``mano``):
            a workflow that consumes the import must use the same hand.
        splits: per task ``{"train", "val", "test"}``, the tohgs names of the targets whose stores were
            written, from the task's ``train.txt`` (``train``), ``val.txt`` (``val``: their grasp files)
            and ``test/*.json`` (``test``: the evaluation's configurations); targets with a rejected mesh
            are left out (their stores are written, reported as a problem).
    """

    root: str
    out: str
    hand: str = ""
    table_top: float = TABLE_HEIGHT
    files_read: int = 0
    problems: list[dict[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    tasks: dict[str, dict[str, int]] = field(default_factory=dict)
    objects: dict[str, int] = field(default_factory=lambda: {"ok": 0, "rejected": 0})
    splits: dict[str, dict[str, list[str]]] = field(default_factory=dict)

    @property
    def n_problems(self) -> int:
        return len(self.problems)

    def problem(self, path: str, kind: str, reason: str) -> None:
        self.problems.append({"path": path, "kind": kind, "reason": reason})
        log.warning("%s (%s): %s", path, kind, reason)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "n_problems": self.n_problems}



# --- objects and supports --------------------------------------------------------------------------------

def _import_object(reader: _Reader, official: str, brick: bool, out_dir: Path, density: float,
                   decomposition: DecompositionSettings, cache_dir: str | Path | None,
                   limits: MeshLimits | None = None) -> dict[str, Any]:
    """Write one object's folder as the objects stage does (:func:`tohgs.assets.objects.prepare_object`),
    from the official mesh at scale 1 (it is in metres).

    The mesh is repaired and validated (a CoACD file's parts are fused into one solid), moved so that its
    centre of mass is the origin (``official_offset`` in ``meta.json`` is that centre in the official mesh
    frame, m); the collision parts are the official convex parts (hulls, vertex-capped), or, for a one-body
    mesh (the bricks), tohgs's convex decomposition. A mesh that fails is a rejected object (``meta.json``
    with the reason), as in the objects stage.
    """
    name = object_name(official, brick)
    rel = mesh_path(official, brick)
    meta: dict[str, Any] = {"name": name, "source": "official", "path": rel, "brick": None,
                            "task_set": TASK_SET_BRICKS if brick else TASK_SET_OBJECTS, "official_name": official,
                            "status": "ok", "reason": ""}
    with atomic_dir(out_dir / name) as tmp:
        try:
            if not reader.exists(rel):
                raise MeshError(f"{rel}: file not found")
            raw = load_mesh(reader.hash(rel), limits)
            mesh, repairs = repair_and_validate(raw)
            centre = np.asarray(mesh.center_mass, dtype=np.float64)
            mesh.apply_translation(-centre)
            bodies = raw.split(only_watertight=False)
            if len(bodies) > 1:
                parts = [cap_hull_vertices(b.convex_hull, decomposition.max_hull_vertices) for b in bodies]
                for p in parts:
                    p.apply_translation(-centre)
                method = "official-coacd"
            else:
                parts, method = convex_decomposition(mesh, decomposition, cache_dir)
        except Exception as exc:  # noqa: BLE001 - a bad mesh is a rejected object, never a crash
            reason = str(exc) if isinstance(exc, MeshError) else f"invalid mesh ({type(exc).__name__}: {exc})"
            meta.update(status="rejected", reason=reason)
            write_json(tmp / "meta.json", meta)
            return meta
        mp = mass_properties(mesh, density)
        mesh.export(tmp / OBJECT_MESH)
        write_obj_parts(tmp / COLLISION_MESH, parts)
        (tmp / OBJECT_URDF).write_text(object_urdf(name, mp.mass, mp.inertia))
        meta.update(
            official_offset=centre.tolist(), scale=1.0, extents=mesh.extents.tolist(), bounds=mesh.bounds.tolist(),
            volume=mp.volume, mass=mp.mass, density=density, inertia=mp.inertia.tolist(),
            watertight=bool(mesh.is_watertight), repairs=repairs, n_vertices=len(mesh.vertices),
            n_faces=len(mesh.faces), n_collision_parts=len(parts), decomposition=method,
            collision_volume=float(sum(p.volume for p in parts)))
        record_object_files(tmp, meta, OBJECT_FILES)  # meta.json with the files' checksums, last
    return meta


def _table(reader: _Reader, report: ImportReport, limits: MeshLimits | None = None
           ) -> tuple[float, tuple[float, float, float]]:
    """The official table's top height and size, m, from ``table.obj`` as their code places it; a missing,
    unreadable or absurd table (non-finite vertices, beyond :data:`POSITION_BOUND`) is a reported problem
    and the official code's nominal table is used."""
    rel = "models/table/table.obj"
    if not reader.exists(rel):
        report.problem(rel, "missing", f"no table mesh: its top is taken at z = {TABLE_HEIGHT} m, its size "
                                       f"{TABLE_SCALE} m")
        return TABLE_HEIGHT, TABLE_SCALE
    try:
        v = load_mesh(reader.hash(rel), limits).vertices * np.asarray(TABLE_SCALE)
        if not np.isfinite(v).all():
            raise MeshError(f"{rel}: non-finite vertex coordinates")
        top, size = float(TABLE_HEIGHT + v[:, 2].max()), tuple(float(x) for x in v.max(0) - v.min(0))
        if not (abs(top) <= POSITION_BOUND and all(0 < x <= 2 * POSITION_BOUND for x in size)):
            raise MeshError(f"{rel}: a table of size {reprlib.repr(size)} m with its top at {top:.3g} m")
    except Exception as exc:  # noqa: BLE001 - a bad table is a reported problem, never a crash
        reason = str(exc) if isinstance(exc, MeshError) else f"invalid mesh ({type(exc).__name__}: {exc})"
        report.problem(rel, "mesh", f"{reason.removeprefix(rel + ': ')}; its top is taken at z = {TABLE_HEIGHT} m, "
                                    f"its size {TABLE_SCALE} m")
        return TABLE_HEIGHT, TABLE_SCALE
    return top, size


def _shelf_support(reader: _Reader, official: str, report: ImportReport, limits: MeshLimits | None = None
                   ) -> Support | None:
    """An official shelf as a tohgs :class:`~tohgs.assets.supports.Support`: one box per convex part (its
    bounding box in the shelf's frame: exact for axis-aligned boards and panels; ``params.box_fill`` is the
    parts' volume over the boxes'). No placement surfaces: imported scenes are not generated."""
    rel = shelf_path(official)
    if not reader.exists(rel):
        report.problem(rel, "missing", f"no mesh for shelf '{official}'")
        return None
    try:
        mesh = load_mesh(reader.hash(rel), limits)
        if not np.isfinite(mesh.vertices).all() or np.abs(mesh.vertices).max() > POSITION_BOUND:
            raise MeshError(f"{rel}: non-finite vertex coordinates, or beyond {POSITION_BOUND:g} m")
        parts = mesh.split(only_watertight=False)
        boxes = [Box(tuple(float(x) for x in p.bounds.mean(0)), tuple(float(x) for x in np.ptp(p.bounds, 0) / 2))
                 for p in parts]
        box_volume = sum(8 * float(np.prod(b.half_extents)) for b in boxes)
        fill = float(sum(abs(p.convex_hull.volume) for p in parts) / box_volume) if box_volume > 0 else 0.0
    except Exception as exc:  # noqa: BLE001 - a bad shelf is a reported problem, never a crash
        reason = str(exc) if isinstance(exc, MeshError) else f"invalid mesh ({type(exc).__name__}: {exc})"
        report.problem(rel, "mesh", reason.removeprefix(rel + ": "))
        return None
    return Support(shelf_name(official), "shelf", boxes, [],
                   {"official_name": official, "source": rel, "box_fill": fill})



# --- the importer ----------------------------------------------------------------------------------------

def _read_list(reader: _Reader, rel: str) -> list[str]:
    return [ln.strip() for ln in reader.read(rel).decode("utf-8").splitlines() if ln.strip()]


def _task_files(reader: _Reader, task: str, report: ImportReport) -> dict[str, str]:
    """``{stem: official split}`` of a task's grasp files (``train.txt``/``val.txt``, or Stacking's list); a
    file listed in both ``train.txt`` and ``val.txt`` is in neither, a problem of kind ``split``."""
    base = f"{DATASET_DIR}/{task}"
    present = {p.stem for p in (reader.root / base).glob("*.npy")}
    lists: dict[str, list[str]] = {}
    for split in ("train", "val"):
        rel = f"{base}/{split}.txt"
        if reader.exists(rel):
            try:
                lists[split] = [Path(n).stem for n in _read_list(reader, rel)]
            except (OSError, UnicodeDecodeError) as exc:
                report.problem(rel, "unreadable", f"{exc}: the task's {split} objects are not imported")
        elif task != "stacking":
            report.problem(rel, "missing", f"no {split} list: the task's {split} objects are not imported")
    both: list[str] = []  # stems in train.txt and val.txt
    if task == "stacking":
        files = {b: split for split, bricks in STACKING_SPLIT.items() for b in bricks if b in present}
        absent = [b for bricks in STACKING_SPLIT.values() for b in bricks if b not in present]
        if absent:
            report.notes.append(f"stacking: bricks of the hard-coded split without a file: {absent}")
        for split, names in lists.items():
            if sorted(names) != sorted(STACKING_SPLIT[split]):
                report.notes.append(f"stacking: {split}.txt differs from the hard-coded split; the hard-coded "
                                    "split (the official training code's) is used")
    else:
        files = {s: split for split, names in lists.items() for s in names}
        both = sorted(set(lists.get("train", ())) & set(lists.get("val", ())))
        for stem in both:  # trained on or validated, not both: neither split takes it
            del files[stem]
            report.problem(f"{base}/val.txt", "split",
                           f"'{stem}.npy' is listed in both {base}/train.txt and {base}/val.txt: imported in "
                           "neither split (neither its grasps nor its test configurations)")
    unlisted = sorted(present - set(files) - set(both))
    if unlisted:
        report.notes.append(f"{task}: files in no split, not imported: {[f'{s}.npy' for s in unlisted]}")
    return files


def _load_rows(reader: _Reader, rel: str, task: str, stem: str, test: bool, report: ImportReport) -> list[Row] | None:
    """The rows of one grasp file or test JSON, or None with the problem reported."""
    if not reader.exists(rel):
        report.problem(rel, "missing", "the test configurations of an evaluated (val) object are not there" if test
                       else "listed in the task's split but not there")
        return None
    try:
        data = reader.read(rel)
        content = json.loads(data) if test else load_official_npy(data, rel)
        return parse_rows(task, content, stem, test)
    except Exception as exc:  # noqa: BLE001 - a bad file is counted and reported, never a crash
        msg = str(exc)
        report.problem(rel, "unreadable", msg[len(rel) + 2:] if msg.startswith(f"{rel}: ") else msg)
        return None


@dataclass
class _Frame:
    """How an import maps official names and frames onto tohgs's (see the module's Frames)."""

    table_top: float
    names: dict[str, str] = field(default_factory=dict)  # tohgs object name -> official name
    offsets: dict[str, list[float]] = field(default_factory=dict)  # tohgs name -> centre of mass, official frame
    supports: dict[str, str] = field(default_factory=dict)  # tohgs support name -> official name

    def attrs(self, objects: Iterable[str], supports: Iterable[str], file: str, index: list[int]) -> dict[str, Any]:
        return {"file": file, "index": index, "table_top": self.table_top,
                "names": {n: self.names.get(n, n) for n in objects},
                "offsets": {n: self.offsets.get(n, [0.0, 0.0, 0.0]) for n in objects},
                "supports": {n: self.supports.get(n, n) for n in supports}}


def _scene_set(task: str, target: str, rows: list[Row], frame: _Frame, file: str, config_attrs: dict[str, Any],
               group: bool = True) -> tuple[SceneSet, np.ndarray]:
    """The configurations of ``rows`` and each row's configuration: with ``group``, rows of the same scene
    (:meth:`Row.scene_key`) are one configuration, in the order of first appearance; without, one per row."""
    keys: dict[bytes, int] = {}
    config_of = np.array([keys.setdefault(r.scene_key() if group else bytes(str(i), "ascii"), len(keys))
                          for i, r in enumerate(rows)], dtype=np.int64)
    first = [int(np.flatnonzero(config_of == c)[0]) for c in range(len(keys))]
    brick = task == "stacking"
    firsts = [rows[i] for i in first]
    ours = {n: object_name(n, brick) for r in firsts
            for n in [r.target, *(o for o, _ in r.obstacles), *([r.base[0]] if r.base else [])]}
    objects = sorted(set(ours.values()))
    supports = sorted({shelf_name(r.shelf[0]) if r.shelf else "table" for r in firsts})

    def conv(name: str, pose: np.ndarray) -> np.ndarray:
        return from_official_pose(pose, frame.offsets.get(ours[name], [0.0, 0.0, 0.0]), frame.table_top)

    offs, ob_id, ob_pose = [0], [], []
    for r in firsts:
        ob_id += [objects.index(ours[n]) for n, _ in r.obstacles]
        ob_pose += [conv(n, p) for n, p in r.obstacles]
        offs.append(len(ob_id))
    identity = np.r_[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    scenes = SceneSet(
        task=task, object=object_name(target, brick),
        target_init_pose=np.array([conv(r.target, r.init) for r in firsts]).reshape(-1, 7),
        target_goal_pose=np.array([conv(r.target, r.goal) for r in firsts]).reshape(-1, 7),
        support_id=np.array([supports.index(shelf_name(r.shelf[0]) if r.shelf else "table") for r in firsts],
                            dtype=np.int32),
        support_pose=np.array([from_official_pose(r.shelf[1], None, frame.table_top) if r.shelf else identity
                               for r in firsts]).reshape(-1, 7),
        base_id=np.array([objects.index(ours[r.base[0]]) if r.base else -1 for r in firsts], dtype=np.int32),
        base_pose=np.array([conv(*r.base) if r.base else np.full(7, np.nan) for r in firsts]).reshape(-1, 7),
        obstacle_offsets=np.asarray(offs, dtype=np.int64), obstacle_id=np.asarray(ob_id, dtype=np.int32),
        obstacle_pose=np.array(ob_pose, dtype=np.float64).reshape(-1, 7), objects=objects, supports=supports,
        attrs={"seed": None, "config": config_attrs, "n_requested": len(firsts), "tries": len(firsts),
               "rejections": {}, "official": frame.attrs(objects, supports, file, [rows[i].index for i in first])})
    return scenes, config_of


def _write_task(task: str, target: str, rows: list[Row], file: str, frame: _Frame, out: Path, wrist: np.ndarray,
                config_attrs: dict[str, Any]) -> tuple[int, int]:
    """Write the scene and task-grasp stores of one target's rows; returns (configurations, grasps)."""
    scenes, config_of = _scene_set(task, target, rows, frame, file, config_attrs)
    order = np.argsort(config_of, kind="stable")
    grasp_init = shift_grasp(np.array([rows[i].grasp for i in order]), -frame.table_top)
    grasp_goal = np.empty_like(grasp_init)
    for k, i in enumerate(order):
        c = config_of[i]
        T = pose_matrix(scenes.target_goal_pose[c]) @ np.linalg.inv(pose_matrix(scenes.target_init_pose[c]))
        grasp_goal[k] = transform_grasp(grasp_init[k:k + 1], T, wrist)[0]
    write_scenes(scenes, out / "scenes" / task / f"{scenes.object}.zarr")
    write_task_grasps(
        {"config": config_of[order], "prior_index": np.full(len(rows), NO_PRIOR), "grasp_init": grasp_init,
         "grasp_goal": grasp_goal, "kept_per_config": np.bincount(config_of, minlength=len(scenes))},
        {"task": task, "object": scenes.object, "n_prior_accepted": None, "config": config_attrs,
         "official": {"file": file, "row": [rows[i].index for i in order], "table_top": frame.table_top}},
        out / "grasps" / "task" / task / f"{scenes.object}.zarr")
    return len(scenes), len(rows)


def _write_catalog(metas: list[dict[str, Any]], split: dict[str, str], path: Path) -> None:
    import pandas as pd

    rows = []
    for m in metas:
        ext = m.get("extents", [np.nan] * 3)
        rows.append({
            "name": m["name"], "source": m["source"], "task_set": m["task_set"],
            "split": split.get(m["name"], "") if m["status"] == "ok" else "", "status": m["status"],
            "reason": m["reason"], "scale": m.get("scale", np.nan), "extent_x": ext[0], "extent_y": ext[1],
            "extent_z": ext[2], "volume": m.get("volume", np.nan), "mass": m.get("mass", np.nan),
            "watertight": m.get("watertight", False), "repairs": "; ".join(m.get("repairs", [])),
            "n_collision_parts": m.get("n_collision_parts", 0), "decomposition": m.get("decomposition", ""),
            "source_path": m["path"]})
    df = pd.DataFrame(rows, columns=CATALOG_COLUMNS).sort_values(["task_set", "name"], kind="stable")
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False)


def import_official(root: str | Path, out: str | Path, hand: HandAssets, tasks: Iterable[str] = TASKS,
                    density: float = 500.0, decomposition: DecompositionSettings | None = None,
                    cache_dir: str | Path | None = None, limits: MeshLimits | None = None) -> ImportReport:
    """Import the official TOHGS dataset below ``root`` into tohgs's stores below ``out``.

    The import is written into a temporary folder next to ``out`` and renamed into place only when it is
    complete, so a failed or killed import leaves ``out`` as it was (never new objects next to old scenes).
    ``out`` must be new, empty, or an earlier import (it holds ``import_report.json``), which the new one
    replaces whole.

    Args:
        root: the official tree (``models/``, ``task_oriented_grasps_dataset/``).
        out: the output folder (module docstring: its layout).
        hand: the hand whose rest wrist joint carries a grasp from the initial to the goal pose
            (:func:`tohgs.geometry.grasp.transform_grasp`); the official grasps are MANO's.
        tasks: the tasks to import.
        density: objects' density, kg/m^3 (``objects.density``).
        decomposition: CoACD settings for one-body meshes (the bricks), and the vertex cap of every part.
        cache_dir: CoACD cache root (None: no cache).
        limits: the largest mesh file and face count to parse (None: :class:`MeshLimits`' defaults).

    Returns:
        The report, also written to ``<out>/import_report.json``; ``<out>/checksums.sha256`` lists every
        file read. Every file that cannot be used (unreadable, absurd numbers, a name that becomes the same
        tohgs name as another's, a mesh that fails) is a problem of the report naming it, never a crash.

    Raises:
        FileNotFoundError: ``root`` has no ``task_oriented_grasps_dataset`` folder.
        ValueError: an unknown task, or ``out`` is a file or a non-empty folder that holds no import.
    """
    root, final = Path(root), Path(out)
    if not (root / DATASET_DIR).is_dir():
        raise FileNotFoundError(f"{root}: no '{DATASET_DIR}' folder (not the official TOHGS dataset's root)")
    bad = [t for t in tasks if t not in TASKS]
    if bad:
        raise ValueError(f"unknown tasks {bad} (expected some of {list(TASKS)})")
    if final.exists() and not final.is_dir():
        raise ValueError(f"{final}: not a folder; give the import a new or empty folder")
    if final.is_dir() and any(final.iterdir()) and not (final / "import_report.json").is_file():
        raise ValueError(f"{final}: a non-empty folder that holds no import (no import_report.json); an import "
                         "replaces its output folder whole, so give it a new or empty folder")
    with atomic_dir(final) as tmp:
        report = _import(root, tmp, final, hand, list(tasks), density, decomposition or DecompositionSettings(),
                         cache_dir, limits or MeshLimits())
    log.info("official import into %s: %d files read, %d problems, %s", final, report.files_read, report.n_problems,
             report.tasks)
    return report


def _row_names(r: Row, task: str) -> list[tuple[str, str]]:
    """The ``(kind, official name)`` of the objects (``object`` or ``brick``) and the shelf a row uses."""
    kind = "brick" if task == "stacking" else "object"
    names = [(kind, n) for n in [r.target, *(o for o, _ in r.obstacles), *([r.base[0]] if r.base else [])]]
    return names + ([("shelf", r.shelf[0])] if r.shelf else [])


def _tohgs_name(key: tuple[str, str]) -> str:
    """tohgs's name of an official ``(kind, name)``: an object's, a brick's or a shelf's (support) name."""
    kind, official = key
    return shelf_name(official) if kind == "shelf" else object_name(official, kind == "brick")


def _official_path(key: tuple[str, str]) -> str:
    """The official mesh of ``(kind, name)``, relative to the tree's root."""
    kind, official = key
    return shelf_path(official) if kind == "shelf" else mesh_path(official, kind == "brick")


def _name_clashes(loaded: list[tuple[str, str, str, list[Row], bool]], report: ImportReport
                  ) -> list[tuple[str, str, str, list[Row], bool]]:
    """Official names (objects, bricks, shelves) that become the same tohgs name (``Shelf_01``, ``shelf-01``):
    in sorted order the first keeps the name; each later one is a problem naming both files and is left out,
    with every row and test configuration that uses it. Returns ``loaded`` without those rows."""
    first: dict[str, tuple[str, str]] = {}
    clash: dict[tuple[str, str], tuple[str, str]] = {}  # left out -> the one that keeps the name
    for key in sorted({k for task, _, _, rows, _ in loaded for r in rows for k in _row_names(r, task)}):
        kept = first.setdefault(_tohgs_name(key), key)
        if kept != key:
            clash[key] = kept
    if not clash:
        return loaded
    dropped: dict[tuple[str, str], int] = dict.fromkeys(clash, 0)
    out = []
    for task, rel, split, rows, test in loaded:
        keep = []
        for r in rows:
            used = [k for k in _row_names(r, task) if k in clash]
            for k in used:
                dropped[k] += 1
            if not used:
                keep.append(r)
        if keep:
            out.append((task, rel, split, keep, test))
    for key, kept in sorted(clash.items()):
        report.problem(_official_path(key), "name",
                       f"official {key[0]} {key[1]!r} and {kept[0]} {kept[1]!r} ({_official_path(kept)}) both become "
                       f"'{_tohgs_name(key)}': {key[1]!r} is left out, with the {dropped[key]} rows and test "
                       "configurations that use it")
    return out


def _import(root: Path, out: Path, final: Path, hand: HandAssets, tasks: list[str], density: float,
            decomposition: DecompositionSettings, cache_dir: str | Path | None, limits: MeshLimits) -> ImportReport:
    """The import of :func:`import_official`, written below ``out`` (a temporary folder that becomes ``final``)."""
    reader, report = _Reader(root), ImportReport(str(root), str(final), hand=hand.name)
    table_top, table_size = _table(reader, report, limits)
    report.table_top = table_top
    frame = _Frame(table_top)
    wrist = np.asarray(hand.rest_joints[0], dtype=np.float64)
    config_attrs = {"source": "official", "root": str(root)}

    # 1. Read every listed file.
    loaded: list[tuple[str, str, str, list[Row], bool]] = []  # (task, file, split, rows, test)
    for task in tasks:
        stats = report.tasks.setdefault(task, dict.fromkeys(
            ("files", "rows", "configurations", "test_files", "test_configurations", "targets"), 0))
        files = sorted(_task_files(reader, task, report).items())
        for stem, split in tqdm(files, desc=f"read {task}", mininterval=5.0):
            rel = f"{DATASET_DIR}/{task}/{stem}.npy"
            rows = _load_rows(reader, rel, task, stem, False, report)
            if rows is not None:
                loaded.append((task, rel, split, rows, False))
                stats["files"] += 1
            if split == "val":
                rel = f"{DATASET_DIR}/{task}/test/{stem}.json"
                rows = _load_rows(reader, rel, task, stem, True, report)
                if rows is not None:
                    loaded.append((task, rel, split, rows, True))
                    stats["test_files"] += 1
    loaded = _name_clashes(loaded, report)

    # 2. Objects, supports and the catalog.
    wanted: dict[str, tuple[str, bool]] = {}  # tohgs name -> (official name, brick)
    shelves: set[str] = set()
    split_of: dict[str, str] = {}
    for task, _, split, rows, _ in loaded:
        for r in rows:
            for kind, n in _row_names(r, task):
                if kind == "shelf":
                    shelves.add(n)
                else:
                    wanted[object_name(n, kind == "brick")] = (n, kind == "brick")
            split_of.setdefault(object_name(r.target, task == "stacking"), SPLIT_OF[split])
    metas = []
    for ours, (official, brick) in tqdm(sorted(wanted.items()), desc="objects", mininterval=5.0):
        meta = _import_object(reader, official, brick, out / "objects", density, decomposition, cache_dir, limits)
        metas.append(meta)
        frame.names[ours] = official
        if meta["status"] == "ok":
            frame.offsets[ours] = meta["official_offset"]
            report.objects["ok"] += 1
        else:
            report.objects["rejected"] += 1
            report.problem(meta["path"], "mesh", f"object '{official}' rejected: {meta['reason']}")
    _write_catalog(metas, split_of, out / "objects" / "catalog.csv")
    supports = [make_table(table_size)]
    for official in sorted(shelves):
        frame.supports[shelf_name(official)] = official
        s = _shelf_support(reader, official, report, limits)
        supports += [s] if s is not None else []
    with atomic_dir(out / "objects" / "supports") as tmp:
        for s in supports:
            s.mesh().export(tmp / f"{s.name}.obj")
        write_json(tmp / "supports.json", {"supports": [s.to_dict() for s in supports],
                                           "official": {"table_top": table_top, "table_size": list(table_size)}})

    # 3. The stores: rows with grasps per target; test configurations per target, in the JSON's order.
    # A grasp file holds one target (the file's object); a test JSON names its targets, so two could clash.
    written: dict[Path, str] = {}
    accepted = {m["name"] for m in metas if m["status"] == "ok"}
    for task in tasks:
        report.splits[task] = {"train": [], "val": [], "test": []}
    for task, rel, split, rows, test in loaded:
        stats = report.tasks[task]
        for target in sorted({r.target for r in rows}):
            mine = [r for r in rows if r.target == target]
            try:
                if test:  # a test configuration is one JSON entry, never merged with another
                    path = out / "test_scenes" / task / f"{object_name(target, task == 'stacking')}.zarr"
                    if path in written:
                        report.problem(rel, "unreadable", f"test configurations of '{target}' are also in "
                                                          f"{written[path]}; only that file's are imported")
                        continue
                    written[path] = rel
                    scenes, _ = _scene_set(task, target, mine, frame, rel, config_attrs, group=False)
                    if task == "shelving":  # their shelving evaluation uses these configurations only
                        scenes.attrs["official"]["evaluated"] = list(range(50, len(mine), 10))
                    write_scenes(scenes, path)
                    stats["test_configurations"] += len(scenes)
                else:
                    n_configs, n_grasps = _write_task(task, target, mine, rel, frame, out, wrist, config_attrs)
                    stats["configurations"] += n_configs
                    stats["rows"] += n_grasps
                    stats["targets"] += 1
            except Exception as exc:  # noqa: BLE001 - a file whose stores cannot be written is reported
                report.problem(rel, "unreadable", f"the stores of target {target!r} could not be written "
                                                  f"({type(exc).__name__}: {exc}); left out")
                continue
            name = object_name(target, task == "stacking")
            if name in accepted:
                report.splits[task]["test" if test else split].append(name)
            else:
                report.problem(rel, "mesh", f"target '{target}' has no accepted mesh: its configurations are "
                                            "left out of the splits")
    for task_splits in report.splits.values():
        for k in task_splits:
            task_splits[k] = sorted(set(task_splits[k]))

    report.files_read = len(reader.digests)
    lines = [f"{d}  {p}\n" for p, d in sorted(reader.digests.items())]
    with atomic_path(out / "checksums.sha256") as tmp:
        tmp.write_text("".join(lines), encoding="utf-8", errors="surrogateescape")
    write_json(out / "import_report.json", report.to_dict())
    return report


@dataclass(frozen=True)
class ImportedDataset:
    """What a workflow needs to know of an import before it runs (config ``official.import_dir``).

    Attributes:
        root: the import's folder (``out`` of :func:`import_official`).
        objects: every object of the catalog (accepted or rejected), by tohgs name.
        hand: the hand the import used (:attr:`ImportReport.hand`).
        splits: per imported task ``{"train", "val", "test"}``: target names (:attr:`ImportReport.splits`).
        n_problems: the files the import could not use.
    """

    root: Path
    objects: tuple[str, ...]
    hand: str
    splits: dict[str, dict[str, list[str]]]
    n_problems: int

    def targets(self, task: str) -> list[str]:
        """The targets of ``task`` with scene and task-grasp stores (the train and val splits)."""
        return sorted({*self.splits[task]["train"], *self.splits[task]["val"]})


def read_import(root: str | Path) -> ImportedDataset:
    """The description of an import folder (its ``import_report.json`` and ``objects/catalog.csv``).

    Raises:
        FileNotFoundError: the folder has no report or catalog (naming the command that writes them).
        ValueError: a report without the hand or the splits, or an accepted object whose ``meta.json`` records no
            checksums of its files (written by an older tohgs: import again).
    """
    import pandas as pd

    root = Path(root)
    report_path, catalog_path = root / "import_report.json", root / "objects" / "catalog.csv"
    for p in (report_path, catalog_path):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: not found; write the import first: python -m tohgs.official "
                                    f"import <official root> {root}")
    report = json.loads(report_path.read_text())
    if not report.get("hand") or not isinstance(report.get("splits"), dict):
        raise ValueError(f"{report_path}: no 'hand' or 'splits' (an import by an older tohgs): import again")
    catalog = pd.read_csv(catalog_path, usecols=["name", "status"])
    for name in catalog.name[catalog.status == "ok"]:
        meta_path = root / "objects" / name / "meta.json"
        try:
            files = json.loads(meta_path.read_text()).get("files")
        except (OSError, ValueError) as exc:
            raise ValueError(f"{meta_path}: unreadable ({exc}): import again") from exc
        if not isinstance(files, dict):
            raise ValueError(f"{meta_path}: no checksums of the object's files (an import by an older tohgs): "
                             "import again")
    return ImportedDataset(root, tuple(sorted(catalog.name)), report["hand"], report["splits"],
                           int(report.get("n_problems", 0)))

