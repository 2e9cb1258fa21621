"""The official TOHGS dataset (Liu, Chao, Chen, ICCV 2025): an importer into tohgs's stores and an exporter of
tohgs's predictions into the official evaluation's output format. ``docs/official_dataset.md`` is the guide.

**What the importer reads** (below ``root``; paths relative to it):

- ``models/meshdata/<obj>/coacd/decomposed_scaled.obj``: the Placing/Shelving objects and obstacles (their
  CoACD convex parts, metres); ``models/brick/<A..X>/textured_simple.obj``: the Stacking bricks;
  ``models/selected_shelf/<shelf>/coacd/decomposed.obj``: the shelves; ``models/table/table.obj``: the
  table (their code scales it by 1.5 x 1.0 x 0.05 and puts it at z = 0.6).
- ``task_oriented_grasps_dataset/<task>/``: ``train.txt`` and ``val.txt`` (one ``<obj>.npy`` per line;
  Stacking's split is hard-coded in their code, :data:`STACKING_SPLIT`), ``<obj>.npy`` (a pickled dict of
  equal-length lists, one row per grasp) and ``test/<obj>.json`` (the evaluation's configurations).

Row keys: Placing ``init_pose``, ``goal_pose`` (7 numbers: xyz m + xyzw quaternion), ``recon_param``
((1, 51) world-frame MANO: translation 3 m, global axis-angle 3, 15 x 3 finger axis-angles; the same order
as tohgs's grasp vector, :mod:`tohgs.geometry.grasp`, so the numbers are taken as they are),
``obstacle_pose`` (a list of 7-vectors per row), ``obstacle_name``; Shelving adds ``shelf_pose`` and
``shelf_name``; Stacking has ``init`` and ``goal`` (each ``[base_name, base_pose7, grasped_name,
grasped_pose7]``) and ``recon_parms`` (sic). Test JSON: the same scene keys per configuration, and
``grasped_obj_name`` (one string for Placing, a list per configuration for Shelving).

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

**Frames.** tohgs's world has the table's top at z = 0 and every object's mesh frame at its centre of mass;
the official world has the table's top at ``table_top`` (measured from ``table.obj``) and the meshes' own
frames. An official pose ``(R, p)`` of an object whose centre of mass is ``c`` (its mesh frame) becomes
``(R, p + R c - table_top e_z)``; a grasp's translation moves by ``-table_top e_z``
(:func:`from_official_pose`, :func:`to_official_pose`). The scene stores record both (attrs ``official``),
so the exporter writes the official frame back exactly.

**Configurations.** The official dataset stores one grasp per row, each row with its own scene. Rows with
identical scenes (bit-identical init pose, goal pose, obstacles, shelf, base) are one configuration with
several grasps; other rows are a configuration each. This loses nothing (each grasp keeps its row, attrs
``official.row`` of the task-grasp store) and gives the stages what they expect from a task-grasp store:
the grasps of one scene side by side.

**Unreadable files** (a bad pickle, a refused pickle global, missing keys, unequal list lengths, bad
shapes, a position beyond :data:`POSITION_BOUND` of the origin, a missing listed file, a mesh that fails
validation or exceeds the mesh limits, an official name that becomes the same tohgs name as another's) are
counted and reported with their reasons (:class:`ImportReport`, ``import_report.json``), never skipped
silently and never a crash. Pickles are read with a restricted unpickler (:func:`safe_loads`): numpy arrays,
numpy scalars and plain containers only; an ``.npy`` header's shape and dtype are checked before its data,
and every pose and grasp's shape before an array is built from it (a small file of shared references can
describe gigabytes). An import is written into a temporary folder and renamed into place when complete.

**The exporter** (:func:`export_official`) writes a prediction store as ``<run_dir>/<obj>.npy`` files of the
official evaluation: a pickled dict with per grasp ``init_hand_vertex`` and ``goal_hand_vertex`` ((V, 3)
float32, metres, official world frame; V is the hand model's vertex count: 778 for MANO, 1609 for the
default anny hand), ``init_pose``, ``goal_pose``, and per task the obstacles, shelf and grasped object.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import logging
import pickle
import reprlib
import unicodedata
import zlib
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from tohgs.assets.decomposition import DecompositionSettings, cap_hull_vertices, convex_decomposition
from tohgs.assets.manifest import record_object_files
from tohgs.assets.mesh import (COLLISION_MESH, OBJECT_MESH, OBJECT_URDF, MeshError, MeshLimits, load_mesh,
                               mass_properties, repair_and_validate)
from tohgs.assets.objects import CATALOG_COLUMNS, OBJECT_FILES, _urdf, _write_obj_parts
from tohgs.assets.sources import TASK_SET_BRICKS, TASK_SET_OBJECTS, sanitise
from tohgs.assets.supports import Box, Support, make_table
from tohgs.data.predictions import read_predictions
from tohgs.data.scenes import SceneSet, read_scenes, write_scenes
from tohgs.data.task_grasps import write_task_grasps
from tohgs.geometry.grasp import GRASP_DIM, pose_matrix, transform_grasp
from tohgs.hand.assets import HandAssets
from tohgs.hand.mano_backend import _NUMPY_GLOBALS, UnsafePickleError
from tohgs.io import atomic_dir, atomic_path, write_json

log = logging.getLogger(__name__)

TASKS = ("placing", "shelving", "stacking")
DATASET_DIR = "task_oriented_grasps_dataset"
#: The Stacking split, hard-coded in the official training code (no train.txt / val.txt is read for it).
STACKING_SPLIT = {"train": tuple("ACDEGHJLMOPQSTUWX"), "val": tuple("FIKNRV")}
#: Where the official code puts the table: its scale of ``table.obj`` and the height of its origin, metres.
TABLE_SCALE = (1.5, 1.0, 0.05)
TABLE_HEIGHT = 0.6
#: ``prior_index`` of an imported task grasp: it comes from no prior store.
NO_PRIOR = -1
#: Our split of the official lists: their evaluation reads ``val.txt``, so it is our test split.
SPLIT_OF = {"train": "train", "val": "test"}
_GRASP_KEY = {"placing": "recon_param", "shelving": "recon_param", "stacking": "recon_parms"}
_SCENE_KEYS = {"placing": ("init_pose", "goal_pose", "obstacle_pose", "obstacle_name"),
               "shelving": ("init_pose", "goal_pose", "obstacle_pose", "obstacle_name", "shelf_pose", "shelf_name"),
               "stacking": ("init", "goal")}
_QUAT_TOL = 1e-3  # largest |norm - 1| of an official quaternion that is renormalised rather than refused
#: The farthest an official position (a pose's or a grasp's translation) may lie from the official world's
#: origin, m: their scenes span a 1.5 m table; 1e6 m is a damaged file, refused rather than imported.
POSITION_BOUND = 10.0
#: The largest magnitude of a grasp's axis-angle component, rad (two full turns): beyond it no hand pose.
ANGLE_BOUND = 4 * np.pi
#: The most obstacles of one official row (their scenes have a handful): a bound on what a file of shared
#: references (a list of one pose repeated) can make the importer build.
MAX_OBSTACLES = 64


# --- the restricted unpickler ----------------------------------------------------------------------------

#: Globals an official pickle may name: numpy's array, dtype and scalar constructors (the MANO reader's
#: set), numpy's out-of-band buffer constructor and the bytes decoder of protocol-2 pickles.
_ALLOWED_GLOBALS = frozenset(_NUMPY_GLOBALS | {
    ("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer"), ("_codecs", "encode")})


class _DatasetUnpickler(pickle.Unpickler):
    """Builds numpy arrays, numpy scalars and plain containers; any other global is refused."""

    def find_class(self, module: str, name: str) -> Any:
        import importlib

        if (module, name) in _ALLOWED_GLOBALS:
            return getattr(importlib.import_module(module), name)
        raise UnsafePickleError(f"refusing global '{module}.{name}' (only numpy arrays and plain containers)")


def safe_loads(data: bytes, source: str = "pickle") -> Any:
    """Unpickle ``data`` allowing only numpy arrays, numpy scalars and plain containers.

    Raises:
        ValueError: a refused global (a pickle that would build another class or call a function) or an
            unreadable pickle; the message names ``source``.
    """
    try:
        return _DatasetUnpickler(io.BytesIO(data), encoding="latin1").load()
    except UnsafePickleError as exc:
        raise ValueError(f"{source}: {exc}") from exc
    except Exception as exc:
        raise ValueError(f"{source}: not a readable pickle ({type(exc).__name__}: {exc})") from exc


def load_official_npy(data: bytes, source: str = "npy") -> Any:
    """The object stored in an official ``.npy`` (``np.save`` of a dict) or a plain pickle file, read safely.

    An ``.npy`` of an object array is its header and a pickle of the array: the header is parsed by numpy,
    the pickle by :func:`safe_loads`; a 0-d object array gives its item (the dict). The header's shape and
    dtype are checked before the data is read: an object array must be 0-d (what ``np.save`` of a dict
    writes), another array must hold exactly the bytes its header declares (numpy would allocate the
    declared size first).

    Raises:
        ValueError: unreadable or refused (the message names ``source``).
    """
    if not data.startswith(b"\x93NUMPY"):
        return safe_loads(data, source)
    fh = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(fh)
        read_header = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
        if version not in read_header:
            raise ValueError(f"unsupported .npy version {version}")
        shape, _, dtype = read_header[version](fh)
    except Exception as exc:
        raise ValueError(f"{source}: not a readable .npy header ({exc})") from exc
    if not dtype.hasobject:
        body = len(data) - fh.tell()
        declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
        if declared != body:
            raise ValueError(f"{source}: the .npy header declares {dtype} {shape} ({declared} bytes) but the file "
                             f"holds {body} bytes of data")
        fh.seek(0)
        return np.lib.format.read_array(fh, allow_pickle=False)
    if shape != ():
        raise ValueError(f"{source}: an object array of shape {shape}, expected a 0-d one holding a dict (what "
                         "np.save of the official dict writes); not unpickled")
    arr = safe_loads(fh.read(), source)
    if not isinstance(arr, np.ndarray):
        raise ValueError(f"{source}: the .npy body is a {type(arr).__name__}, expected an object array")
    return arr.item() if arr.ndim == 0 else arr


# --- frames --------------------------------------------------------------------------------------------

def _fits(v: Any, shape: tuple[int, ...]) -> bool:
    """Whether ``v`` (nested lists, tuples, numpy arrays, numbers) has ``shape`` with real numbers at the
    leaves, decided without building an array: at most ``prod(shape)`` leaves are visited, so a structure of
    shared references that would expand into gigabytes is refused at its first wrong length."""
    if isinstance(v, np.ndarray) and v.dtype != object:
        return v.shape == shape and v.dtype.kind in "iuf"
    if not shape:
        return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
    if isinstance(v, np.ndarray):
        if v.ndim == 0 or len(v) != shape[0]:
            return False
    elif not isinstance(v, (list, tuple)) or len(v) != shape[0]:
        return False
    return all(_fits(x, shape[1:]) for x in v)


def _describe(v: Any) -> str:
    """A short description of a value for a message (type and length or shape, never its whole repr)."""
    if isinstance(v, np.ndarray):
        return f"an array of shape {v.shape} ({v.dtype})"
    if isinstance(v, (list, tuple)):
        return f"a {type(v).__name__} of length {len(v)}"
    return f"{type(v).__name__} {reprlib.repr(v)}"


def _numbers(v: Any, shapes: tuple[tuple[int, ...], ...], what: str) -> np.ndarray:
    """``v`` as a finite float64 array of the first of ``shapes`` it has (checked before it is built)."""
    for shape in shapes:
        if _fits(v, shape):
            a = np.asarray(v, dtype=np.float64).reshape(shape)
            if not np.isfinite(a).all():
                raise ValueError(f"{what}: non-finite numbers")
            return a
    raise ValueError(f"{what}: {_describe(v)}, expected numbers of shape {' or '.join(map(str, shapes))}")


def _unit_pose(pose: Any, what: str) -> np.ndarray:
    """A ``[x, y, z, qx, qy, qz, qw]`` pose as float64 (7,) with its quaternion renormalised; a position
    beyond :data:`POSITION_BOUND` is refused."""
    p = _numbers(pose, ((7,),), f"{what} (xyz + xyzw quaternion)")
    if np.abs(p[:3]).max() > POSITION_BOUND:
        raise ValueError(f"{what}: position {reprlib.repr(p[:3].tolist())} m is beyond {POSITION_BOUND:g} m of the "
                         "official world's origin")
    n = np.linalg.norm(p[3:])
    if abs(n - 1.0) > _QUAT_TOL:
        raise ValueError(f"{what}: quaternion of norm {n:.6g}, not a rotation")
    return np.r_[p[:3], p[3:] / n]


def from_official_pose(pose: np.ndarray, offset: np.ndarray | None = None, table_top: float = 0.0) -> np.ndarray:
    """An official pose in tohgs's frames.

    Args:
        pose: (7,) official pose of an object's mesh frame (m, xyzw quaternion).
        offset: (3,) the object's centre of mass in its official mesh frame, m (None: 0, a support).
        table_top: height of the table's top in the official world, m.

    Returns:
        (7,) the pose of tohgs's mesh frame (centre of mass at the origin) in tohgs's world (table top at 0).
    """
    p = _unit_pose(pose, "pose")
    c = np.zeros(3) if offset is None else np.asarray(offset, dtype=np.float64)
    R = Rotation.from_quat(p[3:]).as_matrix()
    return np.r_[p[:3] + R @ c - [0.0, 0.0, table_top], p[3:]]


def to_official_pose(pose: np.ndarray, offset: np.ndarray | None = None, table_top: float = 0.0) -> np.ndarray:
    """The inverse of :func:`from_official_pose`: (7,) tohgs pose -> (7,) official pose."""
    p = np.asarray(pose, dtype=np.float64)
    c = np.zeros(3) if offset is None else np.asarray(offset, dtype=np.float64)
    R = Rotation.from_quat(p[3:]).as_matrix()
    return np.r_[p[:3] - R @ c + [0.0, 0.0, table_top], p[3:]]


def shift_grasp(grasp: np.ndarray, dz: float) -> np.ndarray:
    """(B, 51) grasps moved by ``dz`` metres along world z (a hand's translation moves every vertex by it)."""
    g = np.array(grasp, dtype=np.float64, copy=True).reshape(-1, GRASP_DIM)
    g[:, 2] += dz
    return g


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
        """Record the digest of a file another reader (trimesh) will parse; returns its path."""
        self.read(rel)
        return self.root / rel


@dataclass
class ImportReport:
    """What an import read, wrote and could not use.

    Attributes:
        root, out: the official tree and the output folder.
        table_top: height of the official table's top, m (the z shift of every pose).
        files_read: files read (each has a line in ``checksums.sha256``).
        problems: per unreadable or missing file ``{"path", "kind", "reason"}``; ``kind`` is ``unreadable``
            (also absurd numbers: a position beyond :data:`POSITION_BOUND`, a wrong shape), ``missing``,
            ``mesh`` (a mesh that failed validation) or ``name`` (an official name that becomes the same tohgs
            name as another's; both files named).
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


@dataclass
class _Row:
    """One official row (a grasp with its scene) or test configuration, in the official frame.

    ``init``/``goal``: (7,) target poses; ``grasp``: (51,) or None (test); ``obstacles``: (name, (7,) pose);
    ``shelf`` and ``base``: (name, (7,) pose) or None.
    """

    index: int
    target: str
    init: np.ndarray
    goal: np.ndarray
    grasp: np.ndarray | None
    obstacles: list[tuple[str, np.ndarray]]
    shelf: tuple[str, np.ndarray] | None
    base: tuple[str, np.ndarray] | None

    def scene_key(self) -> bytes:
        """The bytes that make two rows the same configuration (exact equality of the scene)."""
        parts = [self.target.encode(), self.init.tobytes(), self.goal.tobytes()]
        for extra in (self.shelf, self.base, *self.obstacles):
            parts += [b"|", b"-" if extra is None else extra[0].encode() + extra[1].tobytes()]
        return b"\0".join(parts)


def _name(v: Any, what: str) -> str:
    """A name from a str, a numpy string scalar or a 0-d string array (their ``.item()`` quirk)."""
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v.item()
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if not isinstance(v, str) or not v:
        raise ValueError(f"{what}: expected a name, got {_describe(v)}")
    if ("/" in v or "\\" in v or v in (".", "..") or len(v) > 255
            or any(unicodedata.category(c) in ("Cc", "Cs") for c in v)):
        raise ValueError(f"{what}: {reprlib.repr(v)} is not a file name (names become paths below the root)")
    return str(v)


def _as_list(v: Any, what: str) -> list:
    if isinstance(v, np.ndarray) and v.ndim >= 1:
        return list(v)
    if isinstance(v, (list, tuple)):
        return list(v)
    raise ValueError(f"{what}: a {type(v).__name__}, expected a list")


def _grasp51(v: Any, what: str) -> np.ndarray:
    """A (1, 51) or (51,) official grasp as float64 (51,); a translation beyond :data:`POSITION_BOUND` or an
    axis-angle component beyond :data:`ANGLE_BOUND` is refused."""
    g = _numbers(v, ((1, GRASP_DIM), (GRASP_DIM,)), what).reshape(GRASP_DIM)
    if np.abs(g[:3]).max() > POSITION_BOUND:
        raise ValueError(f"{what}: translation {reprlib.repr(g[:3].tolist())} m is beyond {POSITION_BOUND:g} m of "
                         "the official world's origin")
    if np.abs(g[3:]).max() > ANGLE_BOUND:
        raise ValueError(f"{what}: an axis-angle component of {np.abs(g[3:]).max():.3g} rad, beyond "
                         f"{ANGLE_BOUND:.3g} (two turns)")
    return g


def _stack_entry(v: Any, what: str) -> tuple[str, np.ndarray, str, np.ndarray]:
    e = _as_list(v, what)
    if len(e) != 4:
        raise ValueError(f"{what}: {len(e)} entries, expected [base_name, base_pose, grasped_name, grasped_pose]")
    return (_name(e[0], f"{what}[0]"), _unit_pose(e[1], f"{what}[1]"), _name(e[2], f"{what}[2]"),
            _unit_pose(e[3], f"{what}[3]"))


def _parse_rows(task: str, data: Any, stem: str, test: bool) -> list[_Row]:
    """The rows of one official ``.npy`` (``test=False``) or test JSON (``test=True``) of ``task``.

    Args:
        task: ``placing``, ``shelving`` or ``stacking``.
        data: the loaded dict.
        stem: the file's object (its name without ``.npy`` / ``.json``).
        test: a test JSON (no grasps; the target from ``grasped_obj_name``) rather than a grasp file.

    Raises:
        ValueError: not a dict, missing keys, unequal list lengths, a bad shape or name (the message names
            the key and row).
    """
    if not isinstance(data, dict):
        raise ValueError(f"expected a dict at the top, got {type(data).__name__}")
    keys = list(_SCENE_KEYS[task]) + ([] if test else [_GRASP_KEY[task]])
    if test and task != "stacking":
        keys.append("grasped_obj_name")
    missing = [k for k in keys if k not in data]
    if missing:
        raise ValueError(f"missing keys {missing} (the file has {sorted(map(str, data))})")
    cols = {k: _as_list(data[k], k) for k in keys if k != "grasped_obj_name"}
    targets = None
    if test and task != "stacking":
        g = data["grasped_obj_name"]
        if isinstance(g, str):  # Placing: one name for the file; Shelving: a list, one per configuration
            targets = [_name(g, "grasped_obj_name")] * len(cols[keys[0]])
        else:
            targets = _as_list(g, "grasped_obj_name")
        cols["grasped_obj_name"] = targets
    lengths = {k: len(v) for k, v in cols.items()}
    if len(set(lengths.values())) > 1:
        raise ValueError("unequal list lengths: " + ", ".join(f"{k} {n}" for k, n in lengths.items()))
    rows = []
    for i in range(len(cols[keys[0]])):
        grasp = None if test else _grasp51(cols[_GRASP_KEY[task]][i], f"{_GRASP_KEY[task]}[{i}]")
        if task == "stacking":
            base, base_pose, target, init = _stack_entry(cols["init"][i], f"init[{i}]")
            g_base, _, g_target, goal = _stack_entry(cols["goal"][i], f"goal[{i}]")
            if (g_base, g_target) != (base, target):
                raise ValueError(f"goal[{i}]: bricks ({g_base}, {g_target}) differ from init's ({base}, {target})")
            if not test and target != stem:
                raise ValueError(f"init[{i}]: grasped brick '{target}' is not the file's brick '{stem}'")
            rows.append(_Row(i, target, init, goal, grasp, [], None, (base, base_pose)))
            continue
        names = _as_list(cols["obstacle_name"][i], f"obstacle_name[{i}]")
        poses = _as_list(cols["obstacle_pose"][i], f"obstacle_pose[{i}]")
        if max(len(names), len(poses)) > MAX_OBSTACLES:
            raise ValueError(f"row {i}: {len(names)} obstacle names and {len(poses)} poses, more than "
                             f"{MAX_OBSTACLES} obstacles")
        if len(names) != len(poses):
            raise ValueError(f"row {i}: {len(names)} obstacle names but {len(poses)} obstacle poses")
        obstacles = [(_name(n, f"obstacle_name[{i}][{j}]"), _unit_pose(p, f"obstacle_pose[{i}][{j}]"))
                     for j, (n, p) in enumerate(zip(names, poses))]
        shelf = None
        if task == "shelving":
            shelf = (_name(cols["shelf_name"][i], f"shelf_name[{i}]"),
                     _unit_pose(cols["shelf_pose"][i], f"shelf_pose[{i}]"))
        target = stem if targets is None else _name(targets[i], f"grasped_obj_name[{i}]")
        rows.append(_Row(i, target, _unit_pose(cols["init_pose"][i], f"init_pose[{i}]"),
                         _unit_pose(cols["goal_pose"][i], f"goal_pose[{i}]"), grasp, obstacles, shelf, None))
    return rows


# --- objects and supports --------------------------------------------------------------------------------

def _sanitised(official: str) -> str:
    """An official name in the wildcard alphabet (:func:`tohgs.assets.sources.sanitise`); a name with no letter
    or digit of it (``日本``) becomes ``u<CRC-32 of its UTF-8>``, as a user folder's file does."""
    try:
        return sanitise(official)
    except ValueError:
        return f"u{zlib.crc32(official.encode('utf-8', 'surrogateescape')):08x}"


def object_name(official: str, brick: bool) -> str:
    """tohgs's name of an official object: ``off-<name>``, or ``off-brick-<name>`` for a brick."""
    return f"off-brick-{_sanitised(official)}" if brick else f"off-{_sanitised(official)}"


def shelf_name(official: str) -> str:
    """tohgs's support name of an official shelf: ``shelf-<name>``."""
    return f"shelf-{_sanitised(official)}"


def shelf_path(official: str) -> str:
    """The official mesh of a shelf, relative to the tree's root."""
    return f"models/selected_shelf/{official}/coacd/decomposed.obj"


def mesh_path(official: str, brick: bool) -> str:
    """The official mesh of an object or brick, relative to the tree's root."""
    if brick:
        return f"models/brick/{official}/textured_simple.obj"
    return f"models/meshdata/{official}/coacd/decomposed_scaled.obj"


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
        _write_obj_parts(tmp / COLLISION_MESH, parts)
        (tmp / OBJECT_URDF).write_text(_urdf(name, mp.mass, mp.inertia))
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
    """``{stem: official split}`` of a task's grasp files (``train.txt``/``val.txt``, or Stacking's list)."""
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
    unlisted = sorted(present - set(files))
    if unlisted:
        report.notes.append(f"{task}: files in no split, not imported: {[f'{s}.npy' for s in unlisted]}")
    return files


def _load_rows(reader: _Reader, rel: str, task: str, stem: str, test: bool, report: ImportReport) -> list[_Row] | None:
    """The rows of one grasp file or test JSON, or None with the problem reported."""
    if not reader.exists(rel):
        report.problem(rel, "missing", "the test configurations of an evaluated (val) object are not there" if test
                       else "listed in the task's split but not there")
        return None
    try:
        data = reader.read(rel)
        content = json.loads(data) if test else load_official_npy(data, rel)
        return _parse_rows(task, content, stem, test)
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


def _scene_set(task: str, target: str, rows: list[_Row], frame: _Frame, file: str, config_attrs: dict[str, Any],
               group: bool = True) -> tuple[SceneSet, np.ndarray]:
    """The configurations of ``rows`` and each row's configuration: with ``group``, rows of the same scene
    (:meth:`_Row.scene_key`) are one configuration, in the order of first appearance; without, one per row."""
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


def _write_task(task: str, target: str, rows: list[_Row], file: str, frame: _Frame, out: Path, wrist: np.ndarray,
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


def _row_names(r: _Row, task: str) -> list[tuple[str, str]]:
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


def _name_clashes(loaded: list[tuple[str, str, str, list[_Row], bool]], report: ImportReport
                  ) -> list[tuple[str, str, str, list[_Row], bool]]:
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
    loaded: list[tuple[str, str, str, list[_Row], bool]] = []  # (task, file, split, rows, test)
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
            raise FileNotFoundError(f"{p}: not found; write the import first: python -m tohgs.data.official "
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


# --- the exporter ----------------------------------------------------------------------------------------

def export_official(predictions: str | Path, scenes_dir: str | Path, hand: HandAssets, run_dir: str | Path,
                    default_table_top: float = TABLE_HEIGHT) -> dict[str, Path]:
    """Write a prediction store in the official evaluation's output format, ``<run_dir>/<obj>.npy``.

    Each file is ``np.save`` of a dict (numpy arrays, lists, strings only), one entry per kept grasp, in the
    order of the official configurations and then the samples (the official evaluation's order):

    - ``init_hand_vertex``, ``goal_hand_vertex``: (V, 3) float32, metres, the official world frame: the
      vertices of ``hand`` posed by the grasp (V = ``len(hand.rest_vertices)``: 778 for MANO, 1609 for anny;
      the official evaluation scripts expect MANO's 778).
    - ``init_pose``, ``goal_pose``: the target's official pose (7 floats), or for Stacking
      ``[base_name, base_pose, grasped_name, grasped_pose]`` (the base at its one stored pose in both).
    - Placing and Shelving: ``obstacle_name``, ``obstacle_pose`` (lists per grasp) and ``grasped_obj``
      (the target's official name); Shelving also ``shelf_name`` and ``shelf_pose``.
    - Added by tohgs (the official readers ignore them): ``init_recon_param``, ``goal_recon_param``
      ((51,) float32 grasps in the official frame), ``config`` (the official configuration index),
      ``sample``, ``hand_model`` and ``n_hand_vertices``.

    Args:
        predictions: a prediction store (:mod:`tohgs.data.predictions`).
        scenes_dir: the scene stores its ``config_index`` refers to (``<scenes_dir>/<task>/<object>.zarr``):
            the importer's ``test_scenes``, or tohgs's own ``results/scenes``.
        hand: the hand that poses the grasps (the one that made them).
        run_dir: the output folder (the official ``result/<run>``).
        default_table_top: the official table top for scene stores that were not imported (tohgs's own:
            object names and mesh frames are then kept as they are).

    Returns:
        ``{file stem: path}`` of the files written. A file is named after the official file its
        configurations came from (``test/<obj>.json`` -> ``<obj>.npy``), else after the tohgs object.

    Raises:
        ValueError: a store that cannot be read, or a configuration index outside its scene store.
    """
    arrays, attrs = read_predictions(predictions)
    task, objects = attrs["task"], list(attrs["objects"])
    run_dir = Path(run_dir)
    files: dict[str, list[tuple[tuple[int, int], dict[str, Any]]]] = {}
    grasped: dict[str, str] = {}
    for oid in np.unique(arrays["object_id"]):
        path = Path(scenes_dir) / task / f"{objects[oid]}.zarr"
        scenes = read_scenes(path)
        off = scenes.attrs.get("official") or {}
        top = float(off.get("table_top", default_table_top))
        names, offsets, snames = off.get("names", {}), off.get("offsets", {}), off.get("supports", {})
        stem = Path(off["file"]).stem if off.get("file") else scenes.object
        index = off.get("index") or list(range(len(scenes)))

        def official(name: str, pose: np.ndarray, top: float = top, names: dict = names, offsets: dict = offsets
                     ) -> tuple[str, list[float]]:
            return names.get(name, name), to_official_pose(pose, offsets.get(name), top).tolist()

        target = names.get(scenes.object, scenes.object)
        grasped[stem] = target
        for r in np.flatnonzero(arrays["object_id"] == oid):
            c = int(arrays["config_index"][r])
            if not 0 <= c < len(scenes):
                raise ValueError(f"{predictions}: configuration {c} of '{scenes.object}' is outside {path} "
                                 f"({len(scenes)} configurations)")
            keep = np.flatnonzero(arrays["kept"][r])
            g_init = shift_grasp(arrays["grasp_init"][r, keep], top)
            g_goal = shift_grasp(arrays["grasp_goal"][r, keep], top)
            v_init = hand.vertices(g_init).astype(np.float32)
            v_goal = hand.vertices(g_goal).astype(np.float32)
            _, init = official(scenes.object, scenes.target_init_pose[c])
            _, goal = official(scenes.object, scenes.target_goal_pose[c])
            base = scenes.base(c)
            for k, s in enumerate(keep):
                e: dict[str, Any] = {"init_hand_vertex": v_init[k], "goal_hand_vertex": v_goal[k],
                                     "init_recon_param": g_init[k].astype(np.float32),
                                     "goal_recon_param": g_goal[k].astype(np.float32),
                                     "config": int(index[c]), "sample": int(s)}
                if task == "stacking":
                    b = official(*base) if base is not None else ("", [float("nan")] * 7)
                    e["init_pose"], e["goal_pose"] = [b[0], b[1], target, init], [b[0], b[1], target, goal]
                else:
                    e["init_pose"], e["goal_pose"] = init, goal
                    obs = [official(n, p) for n, p in scenes.obstacles(c)]
                    e["obstacle_name"], e["obstacle_pose"] = [n for n, _ in obs], [p for _, p in obs]
                if task == "shelving":
                    sname, spose = scenes.support(c)
                    e["shelf_name"] = snames.get(sname, sname)
                    e["shelf_pose"] = to_official_pose(spose, None, top).tolist()
                files.setdefault(stem, []).append(((int(index[c]), int(s)), e))
    written = {}
    for stem, entries in files.items():
        entries.sort(key=lambda x: x[0])
        keys = list(entries[0][1]) if entries else []
        output: dict[str, Any] = {k: [e[k] for _, e in entries] for k in keys}
        if task != "stacking":
            output["grasped_obj"] = grasped[stem]
        output.update(hand_model=hand.name, n_hand_vertices=int(len(hand.rest_vertices)))
        path = run_dir / f"{stem}.npy"
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.save(fh, np.array(output, dtype=object), allow_pickle=True)
        written[stem] = path
    log.info("official export: %d files, %d grasps into %s", len(written), sum(len(v) for v in files.values()), run_dir)
    return written


# --- the command line ------------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    """``python -m tohgs.data.official import ROOT OUT`` / ``export PREDICTIONS SCENES_DIR RUN_DIR``."""
    from tohgs.hand import load_hand_assets

    parser = argparse.ArgumentParser(prog="python -m tohgs.data.official", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    imp = sub.add_parser("import", help="official tree -> tohgs stores")
    imp.add_argument("root")
    imp.add_argument("out")
    imp.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    imp.add_argument("--density", type=float, default=500.0)
    imp.add_argument("--cache-dir", default=None)
    imp.add_argument("--max-faces", type=int, default=MeshLimits.max_faces,
                     help="largest mesh to parse, faces (objects.limits.max_faces)")
    imp.add_argument("--max-file-mb", type=float, default=MeshLimits.max_file_mb,
                     help="largest mesh file to parse, MB (objects.limits.max_file_mb)")
    exp = sub.add_parser("export", help="tohgs prediction store -> official result/<run>/<obj>.npy")
    exp.add_argument("predictions")
    exp.add_argument("scenes_dir")
    exp.add_argument("run_dir")
    for p in (imp, exp):
        p.add_argument("--hand", default="anny", choices=("anny", "mano"))
        p.add_argument("--mano-path", default=None)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    hand = load_hand_assets(args.hand, args.mano_path)
    if args.command == "import":
        report = import_official(args.root, args.out, hand, args.tasks, args.density, cache_dir=args.cache_dir,
                                 limits=MeshLimits(args.max_faces, args.max_file_mb))
        for p in report.problems:
            print(f"{p['kind']}: {p['path']}: {p['reason']}")
        print(f"{report.files_read} files read, {report.n_problems} problems; {report.tasks}")
        return 1 if report.n_problems else 0
    for stem, path in export_official(args.predictions, args.scenes_dir, hand, args.run_dir).items():
        print(f"{stem}: {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
