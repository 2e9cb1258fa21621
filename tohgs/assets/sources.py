"""Object sources and the deterministic selection of the objects a run uses.

Three sources, each giving objects a stable name (the Snakemake wildcard):

- ``pybullet_data``: the procedurally generated ``random_urdfs/NNN/NNN.obj`` (names ``pb-rand-NNN``) and a
  curated list of named household meshes shipped with the package (names ``pb-<stem>``).
- ``bricks``: the 23 generated bricks of :mod:`tohgs.assets.bricks` (names ``brick-<shape>``), the Stacking set.
- ``dir``: every .obj/.stl/.ply file in a user folder (names ``dir-<stem>``).

Selection reads only file names, never mesh contents, so it is cheap enough to run when Snakemake parses
the workflow; validation happens per object later and rejections are recorded in the catalog.
"""

from __future__ import annotations

import json
import os
import re
import stat
import unicodedata
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.assets.bricks import brick_names
from tohgs.assets.mesh import MESH_SUFFIXES

#: Task sets: placing/shelving objects, and the stacking bricks.
TASK_SET_OBJECTS = "placing/shelving"
TASK_SET_BRICKS = "stacking"



def task_set(task: str) -> str:
    """The object set a task draws its targets from: the bricks for stacking, the objects otherwise."""
    if task not in ("placing", "stacking", "shelving"):
        raise ValueError(f"unknown task '{task}'")
    return TASK_SET_BRICKS if task == "stacking" else TASK_SET_OBJECTS


#: Named household meshes of pybullet_data that are candidates (paths relative to its data folder).
#: Some do not pass validation (for example the mug, open at its rim): they are recorded as rejected.
PYBULLET_NAMED = (
    "bunny.obj", "duck.obj", "soccerball.obj", "sphere_smooth.obj", "stone.obj", "objects/mug.obj",
    "jenga/jenga.obj", "domino/domino.obj", "torus/torus_textured.obj", "toys/cylinder.obj",
    "toys/prism.obj", "toys/shape_sorter.obj", "toys/cube.obj", "lego/lego.obj", "teddy2_VHACD_CHs.obj",
)

_NAME_RE = re.compile(r"[^a-z0-9]+")


@dataclass(frozen=True)
class ObjectSpec:
    """One selected object.

    Attributes:
        name: the stable identifier, ``[a-z0-9-]+``; also the folder name under ``results/objects``.
        source: ``pybullet_data`` | ``bricks`` | ``dir``.
        task_set: :data:`TASK_SET_OBJECTS` or :data:`TASK_SET_BRICKS`.
        path: absolute path of the source mesh file, or ``None`` for generated bricks.
        brick: the brick shape name for ``bricks``, else ``None``.
    """

    name: str
    source: str
    task_set: str
    path: str | None = None
    brick: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def pybullet_data_root() -> Path:
    """The folder of the installed ``pybullet_data`` package."""
    import pybullet_data

    return Path(pybullet_data.getDataPath())


def sanitise(stem: str) -> str:
    """Lower-case a file stem into the wildcard alphabet ``[a-z0-9-]``."""
    out = _NAME_RE.sub("-", stem.lower()).strip("-")
    if not out:
        raise ValueError(f"cannot make an object name from '{stem}'")
    return out


def pybullet_random_candidates(root: Path | None = None) -> list[ObjectSpec]:
    """The procedurally generated objects under ``random_urdfs`` (about 1000), sorted by name."""
    root = pybullet_data_root() if root is None else root
    files = sorted((root / "random_urdfs").glob("*/*.obj"))
    return [ObjectSpec(f"pb-rand-{f.stem}", "pybullet_data", TASK_SET_OBJECTS, str(f)) for f in files]


def pybullet_named_candidates(root: Path | None = None) -> list[ObjectSpec]:
    """The curated named household meshes of pybullet_data that exist in this installation."""
    root = pybullet_data_root() if root is None else root
    out = []
    for rel in PYBULLET_NAMED:
        f = root / rel
        if f.is_file():
            out.append(ObjectSpec(f"pb-{sanitise(f.stem)}", "pybullet_data", TASK_SET_OBJECTS, str(f)))
    return out


def brick_candidates() -> list[ObjectSpec]:
    """The 23 bricks, in their stable order."""
    return [ObjectSpec(f"brick-{b}", "bricks", TASK_SET_BRICKS, None, b) for b in brick_names()]


def unsafe_path(path: str) -> str | None:
    """Why ``path`` cannot be a workflow input, or None: not valid UTF-8 (bytes Python keeps as surrogates),
    control characters (a newline splits log lines and tables), or braces (Snakemake reads ``{...}`` in an
    input path as a wildcard, and no escaping gets past its check: ``cup{1}.obj`` stopped every command)."""
    try:
        path.encode("utf-8")
    except UnicodeEncodeError:
        return "the name is not valid UTF-8"
    if any(unicodedata.category(c) == "Cc" for c in path):
        return "the name holds control characters"
    if "{" in path or "}" in path:
        return "the name holds '{' or '}', which Snakemake reads as a wildcard in an input path; rename the file"
    return None


def _not_a_file(f: Path) -> str | None:
    """Why the folder entry ``f`` (a mesh suffix) is no file to read, or None."""
    if f.is_symlink() and not f.exists():
        return f"a dangling symbolic link (to {os.readlink(f)!r})"
    if f.is_file():
        return None
    mode = f.stat().st_mode
    kind = ("a folder" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "a device" if stat.S_ISBLK(mode) or stat.S_ISCHR(mode) else "not a regular file")
    return f"{kind}, not a mesh file"


def dir_candidates(folder: str | Path, skipped: list[tuple[str, str]] | None = None) -> list[ObjectSpec]:
    """Every mesh file (.obj/.stl/.ply) directly in ``folder``, sorted; a name taken by an earlier file gets
    the suffix (``cup.obj``, ``cup.stl``: ``dir-cup``, ``dir-cup-stl``).

    A stem with no letter or digit of the name alphabet (``日本.obj``) is named by its CRC-32
    (``dir-u3f2a9c01``: stable, and the catalog's ``source_path`` says which file it is). An entry with a
    mesh suffix that is no regular file (a dangling link, a FIFO, a folder) or whose path is not safe as a
    workflow input (:func:`unsafe_path`: not UTF-8, control characters, braces) is skipped, with
    ``(path, reason)`` appended to ``skipped`` (the workflow logs them and lists them in the catalog).

    Raises:
        FileNotFoundError: the folder does not exist.
        ValueError: the folder's own path is unsafe, or two files would become the same object name (the
            message names both files).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"objects.sources.dir.path: folder '{folder}' does not exist")
    why = unsafe_path(str(folder.resolve()))
    if why:
        raise ValueError(f"objects.sources.dir.path: folder {str(folder)!r} cannot hold workflow inputs: {why}")
    entries = sorted(f for f in folder.iterdir() if f.suffix.lower() in MESH_SUFFIXES)
    out: list[ObjectSpec] = []
    owner: dict[str, Path] = {}
    for f in entries:
        why = _not_a_file(f) or unsafe_path(f.name)
        if not why and unsafe_path(str(f.resolve())):
            why = f"it resolves to {ascii(str(f.resolve()))}: {unsafe_path(str(f.resolve()))}"
        if why:
            if skipped is not None:
                skipped.append((ascii(str(f)) if unsafe_path(str(f)) else str(f), why))
            continue
        try:
            name = f"dir-{sanitise(f.stem)}"
        except ValueError:
            name = f"dir-u{zlib.crc32(f.stem.encode('utf-8')):08x}"
        if name in owner:
            name = f"{name}-{f.suffix.lower().lstrip('.')}"
        if name in owner:
            raise ValueError(f"objects.sources.dir.path: the files '{owner[name].name}' and '{f.name}' in {folder} "
                             f"both become the object name '{name}'; rename one of them")
        owner[name] = f
        out.append(ObjectSpec(name, "dir", TASK_SET_OBJECTS, str(f.resolve())))
    return out


def _choose(candidates: list[ObjectSpec], count: int | None, rng: np.random.Generator, key: str) -> list[ObjectSpec]:
    if count is None or count == len(candidates):
        return list(candidates)
    if count > len(candidates):
        raise ValueError(f"config key '{key}': asks for {count} objects but only {len(candidates)} are available")
    idx = np.sort(rng.choice(len(candidates), size=count, replace=False))
    return [candidates[i] for i in idx]


def select_objects(objects_cfg: dict[str, Any], seed: int, base_dir: str | Path = ".",
                   skipped: list[tuple[str, str]] | None = None) -> list[ObjectSpec]:
    """Select the run's objects from the ``objects`` config block, deterministically for ``seed``.

    Each source draws from its own generator (seeded from ``seed`` and the source), so changing one
    source's count does not change another's selection.

    Args:
        objects_cfg: the validated ``objects`` block of the config.
        seed: the global seed.
        base_dir: folder that a relative ``sources.dir.path`` is resolved against.
        skipped: receives ``(file, reason)`` of the user folder's files that cannot be used.

    Returns:
        The selected objects, sources in the order pybullet_data, bricks, dir, each sorted by name.

    Raises:
        ValueError: a count exceeds its pool, or the selection is empty.
    """
    src = objects_cfg["sources"]
    pb = src["pybullet_data"]
    selected: list[ObjectSpec] = []
    selected += _choose(pybullet_random_candidates(), pb["random_urdfs"], np.random.default_rng([seed, 1]),
                        "objects.sources.pybullet_data.random_urdfs")
    selected += _choose(pybullet_named_candidates(), pb["named"], np.random.default_rng([seed, 2]),
                        "objects.sources.pybullet_data.named")
    selected += _choose(brick_candidates(), src["bricks"]["count"], np.random.default_rng([seed, 3]),
                        "objects.sources.bricks.count")
    if src["dir"]["path"] is not None:
        folder = Path(src["dir"]["path"])
        folder = folder if folder.is_absolute() else Path(base_dir) / folder
        cands = dir_candidates(folder, skipped)
        count = src["dir"]["count"]
        selected += _choose(cands, None if count == 0 else min(count, len(cands)),
                            np.random.default_rng([seed, 4]), "objects.sources.dir.count")
    if not selected:
        raise ValueError("objects.sources: the selection is empty; ask for at least one object")
    names = [s.name for s in selected]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ValueError(f"objects.sources: duplicate object names {sorted(dup)}")
    return selected


def accepted_objects(object_dirs: list[str | Path], task_set: str) -> list[str]:
    """Sorted names of the accepted objects of ``task_set`` among the objects stage's folders (their
    ``meta.json``), for jobs that must not depend on the catalog checkpoint.

    Raises:
        FileNotFoundError: a folder without ``meta.json`` (its objects job did not finish).
    """
    metas = [read_object_meta(d) for d in object_dirs]
    return sorted(m["name"] for m in metas if m["status"] == "ok" and m["task_set"] == task_set)


def read_object_meta(object_dir: str | Path) -> dict[str, Any]:
    """The ``meta.json`` of one object's folder (written by :func:`tohgs.assets.objects.prepare_object`).

    Raises:
        FileNotFoundError: the folder has none (its objects job did not finish).
    """
    meta_path = Path(object_dir) / "meta.json"
    if not meta_path.is_file():
        raise FileNotFoundError(f"{meta_path}: missing; the objects stage did not finish for this object")
    return json.loads(meta_path.read_text())
