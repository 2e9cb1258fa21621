"""The official TOHGS dataset's format: its layout, constants and names, reading its files, and its frames.

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

**Frames.** tohgs's world has the table's top at z = 0 and every object's mesh frame at its centre of mass;
the official world has the table's top at ``table_top`` (measured from ``table.obj``) and the meshes' own
frames. An official pose ``(R, p)`` of an object whose centre of mass is ``c`` (its mesh frame) becomes
``(R, p + R c - table_top e_z)``; a grasp's translation moves by ``-table_top e_z``
(:func:`from_official_pose`, :func:`to_official_pose`). The scene stores record both (attrs ``official``),
so the exporter writes the official frame back exactly.

**Reading.** Pickles are read with the restricted unpickler (:func:`load_official_pickle`, an allow-list
for :func:`tohgs.safe_pickle.restricted_loads`): numpy arrays, numpy scalars and plain containers only; an
``.npy`` header's shape and dtype are checked before its data, and every pose and grasp's shape before an
array is built from it (a small file of shared references can describe gigabytes).
"""

from __future__ import annotations

import io
import reprlib
import unicodedata
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from tohgs.assets.sources import sanitise
from tohgs.hand.layout import GRASP_DIM
from tohgs.safe_pickle import NUMPY_GLOBALS, restricted_loads

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


# --- reading the files -----------------------------------------------------------------------------------

#: Globals an official pickle may name (:func:`tohgs.safe_pickle.restricted_loads`' allow-list): numpy's array,
#: dtype and scalar constructors, numpy's out-of-band buffer constructor and the bytes decoder of protocol-2
#: pickles.
OFFICIAL_GLOBALS = NUMPY_GLOBALS | {
    ("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer"), ("_codecs", "encode")}


def load_official_pickle(data: bytes, source: str = "pickle") -> Any:
    """Unpickle ``data`` allowing only numpy arrays, numpy scalars and plain containers (:data:`OFFICIAL_GLOBALS`).

    Raises:
        ValueError: a refused global (a pickle that would build another class or call a function) or an
            unreadable pickle; the message names ``source``.
    """
    return restricted_loads(data, source, OFFICIAL_GLOBALS, allowed_text="only numpy arrays and plain containers")


def load_official_npy(data: bytes, source: str = "npy") -> Any:
    """The object stored in an official ``.npy`` (``np.save`` of a dict) or a plain pickle file, read safely.

    An ``.npy`` of an object array is its header and a pickle of the array: the header is parsed by numpy,
    the pickle by :func:`load_official_pickle`; a 0-d object array gives its item (the dict). The header's shape and
    dtype are checked before the data is read: an object array must be 0-d (what ``np.save`` of a dict
    writes), another array must hold exactly the bytes its header declares (numpy would allocate the
    declared size first).

    Raises:
        ValueError: unreadable or refused (the message names ``source``).
    """
    if not data.startswith(b"\x93NUMPY"):
        return load_official_pickle(data, source)
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
    arr = load_official_pickle(fh.read(), source)
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



# --- rows ----------------------------------------------------------------------------------------------

@dataclass
class Row:
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


def parse_rows(task: str, data: Any, stem: str, test: bool) -> list[Row]:
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
            rows.append(Row(i, target, init, goal, grasp, [], None, (base, base_pose)))
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
        rows.append(Row(i, target, _unit_pose(cols["init_pose"][i], f"init_pose[{i}]"),
                         _unit_pose(cols["goal_pose"][i], f"goal_pose[{i}]"), grasp, obstacles, shelf, None))
    return rows



# --- names and paths -----------------------------------------------------------------------------------

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

