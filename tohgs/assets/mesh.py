"""Mesh loading, validation, repair, rescaling and mass properties.

Every object that enters tohgs goes through :func:`load_mesh` and :func:`repair_and_validate`: the result is
a single connected, watertight, outward-oriented triangle mesh with positive volume, or a
:class:`MeshError` whose message is the rejection reason written to the catalog.

Units: source meshes come in arbitrary units; after :func:`normalise` everything is in metres, with the
object's centre of mass at the origin and its source orientation kept (z up).
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from tohgs.assets.manifest import check_faces, check_object_file
from tohgs.assets.sources import MESH_SUFFIXES

log = logging.getLogger(__name__)


# Bodies of a multi-body source mesh are inflated by this factor about their own centroids before the
# boolean union, so that pieces that only touch (coplanar faces, as in pybullet_data's random_urdfs)
# fuse into one solid. 0.2 % changes a 10 cm object by 0.1 mm.
TOUCH_INFLATION = 1.002

# A body of a multi-body source mesh that stays open after hole filling and holds less than this fraction
# of the mesh's surface area is a stray fragment (scanned meshes such as the YCB set carry isolated single
# triangles) and is dropped; a larger open body still rejects the mesh.
STRAY_AREA_FRACTION = 1e-3


OBJECT_MESH = "mesh.obj"  # the normalised mesh in an object's folder of the objects stage
OBJECT_URDF = "object.urdf"  # its URDF (mesh.obj as visual, collision.obj as collision, the mass properties)


def _load_recorded(path: Path, name: str, what: str) -> trimesh.Trimesh:
    """The mesh file ``path`` of object ``name``'s folder, loaded as written (``process=False``: merging
    vertices would break seams), after checking it against the checksum its stage recorded; ``what`` names
    it in the errors (the module's readers' Raises)."""
    if not path.is_file():
        raise ValueError(f"{path}: no {what} (is '{name}' an accepted object of the objects stage?)")
    record = check_object_file(path)
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:
        raise ValueError(f"{path}: unreadable {what} ({exc})") from exc
    if len(mesh.faces) == 0:
        raise ValueError(f"{path}: {what} without triangles")
    check_faces(path, len(mesh.faces), record)
    return mesh


def object_mesh(objects_dir: str | Path, name: str) -> trimesh.Trimesh:
    """The normalised mesh of object ``name`` of the objects stage, ``<objects_dir>/<name>/mesh.obj``
    (metres, centre of mass at the origin), loaded as written (no merging: it would break seams), after
    checking the file against the checksum its stage recorded (:mod:`tohgs.assets.manifest`).

    Raises:
        ValueError: the file is missing, unreadable, has no triangles, does not match its checksum, or loads
            with fewer faces than recorded (the message names it).
    """
    return _load_recorded(Path(objects_dir) / name / OBJECT_MESH, name, "object mesh")


COLLISION_MESH = "collision.obj"  # the convex decomposition's parts in an object's folder (one ``o`` group each)


def collision_mesh(objects_dir: str | Path, name: str) -> trimesh.Trimesh:
    """The convex parts of object ``name`` (``<objects_dir>/<name>/collision.obj``, its mesh frame, metres)
    as one mesh: the parts' triangles side by side, overlaps and inner faces kept, as a decomposed mesh file
    loads (the official evaluation voxelises this for PV).

    Raises:
        ValueError: the file is missing, unreadable, has no triangles, does not match its checksum or loads
            with fewer faces than recorded (the message names it).
    """
    return _load_recorded(Path(objects_dir) / name / COLLISION_MESH, name, "collision parts")


class MeshError(ValueError):
    """A mesh that cannot be used; the message is the reason recorded in the catalog."""


@dataclass(frozen=True)
class MeshLimits:
    """The largest source mesh the objects stage takes (config ``objects.limits``), checked before the file is
    parsed: repairing and decomposing a mesh costs memory in proportion to its faces
    (:func:`tohgs.assets.memory.prepare_memory_mb`), and a 10-million-face file once took 8.8 GB.

    Attributes:
        max_faces: most triangles (a polygon of k corners counts k - 2, as it is triangulated).
        max_file_mb: largest file, MB (10^6 bytes); bounds the face count's own pass over the file.
    """

    max_faces: int = 100_000
    max_file_mb: float = 100.0


def count_faces(path: str | Path, stop_above: int | None = None) -> int:
    """The triangles that trimesh takes from a mesh file (``trimesh.load(path, force="mesh", process=False)``, as
    :func:`load_mesh` reads it; a polygon of k corners is the k - 2 triangles it is triangulated into), counted
    without parsing the file into arrays: the file is read a block at a time, so memory does not grow with it.
    The count is never below what trimesh takes (above it only for a malformed file, or one whose reading
    differs between trimesh and the format's specification: the larger reading counts):

    - ``.obj``: the text as trimesh reads it (UTF-8, or the encoding it guesses for a file that is not;
      ``\\r\\n`` read as ``\\n``; a backslash at a line's end joins the next line to it), every line whose first
      non-blank character is ``f`` (``f``, ``f\\t``, ``f1``; trimesh takes the ones without leading blanks) with
      k corners: k - 2 triangles; face lines with the same number of values (``1/2/3`` is 3) count as many
      triangles each as the one with the most corners, as trimesh reads such lines as one table with the first
      line's corners. A face line that holds ``usemtl`` (where trimesh would split it) is refused.
    - ``.stl``: a binary STL (its size is 84 + 50 n bytes): the header's n; an ASCII STL: one triangle per 9
      numbers after the ``vertex`` keywords (any case; trimesh reads the numbers after each keyword up to the
      line's end, and makes triangles of them, ``facet`` or not).
    - ``.ply``: the header, read strictly (one that trimesh could read otherwise is refused), and the body up
      to and through the ``face`` element: the sum over its records of max(k - 2, 0), k the length of the
      record's ``vertex_indices`` (or ``vertex_index``) list; the elements before are skipped (a binary
      element of fixed-size records by a seek). An ASCII body is read as trimesh reads it, one record a line;
      for a binary body the count is the larger of that sum and trimesh's reading, which takes every record
      of an element to be as long as its first.

    Args:
        path: the file.
        stop_above: stop reading once the count exceeds this (at most a block later; the count returned is
            then above ``stop_above``, possibly below the file's whole count); None: count the whole file.

    Raises:
        MeshError: an unsupported suffix, an unreadable file, or one whose triangles cannot be counted
            reliably (a malformed PLY header or record, a truncated binary PLY body, ...); the message names the
            file and the reason.
    """
    from tohgs.assets.face_count import count_triangles

    return count_triangles(Path(path), stop_above)[0]


def check_mesh_limits(path: str | Path, limits: MeshLimits) -> int:
    """Refuse a mesh file beyond ``limits`` before it is parsed; returns its face count (:func:`count_faces`,
    which stops reading once the count exceeds ``max_faces``).

    Raises:
        MeshError: the file is larger than ``max_file_mb``, has more than ``max_faces`` triangles, or its
            triangles cannot be counted (the reason names the file, the size and the setting).
    """
    path = Path(path)
    size_mb = path.stat().st_size / 1e6
    if size_mb > limits.max_file_mb:
        raise MeshError(f"{path}: a file of {size_mb:.1f} MB, larger than objects.limits.max_file_mb = "
                        f"{limits.max_file_mb:g} MB (not parsed; decimate the mesh or raise the limit)")
    from tohgs.assets.face_count import count_triangles

    n, whole = count_triangles(path, limits.max_faces)
    if n > limits.max_faces:
        raise MeshError(f"{path}: {n if whole else f'at least {n}'} faces, more than objects.limits.max_faces = "
                        f"{limits.max_faces} (not parsed: repairing and decomposing it would need more memory than "
                        "the rule asks for; decimate the mesh, or raise the limit with "
                        "resources.rules.prepare_object.mem_mb)")
    return n


@dataclass(frozen=True)
class MassProperties:
    """Rigid-body properties of a normalised mesh (SI units).

    Attributes:
        volume: m^3.
        mass: kg (volume x density).
        center_mass: (3,) m, in the mesh frame.
        inertia: (3, 3) kg m^2 about the centre of mass, mesh-frame axes.
    """

    volume: float
    mass: float
    center_mass: np.ndarray
    inertia: np.ndarray


def load_mesh(path: str | Path, limits: MeshLimits | None = None) -> trimesh.Trimesh:
    """Load a triangle mesh file (.obj/.stl/.ply) as one ``Trimesh`` with texture seams merged.

    Args:
        path: the file.
        limits: the largest file and face count to parse (:func:`check_mesh_limits`, before parsing);
            None: no limit.

    Raises:
        MeshError: the file is missing, beyond ``limits`` (or, with limits, its triangles cannot be counted:
            :func:`count_faces`), cannot be parsed, or holds no triangles.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{path}: unsupported suffix '{path.suffix}' (expected one of {MESH_SUFFIXES})")
    if limits is not None:
        check_mesh_limits(path, limits)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise MeshError(f"{path}: cannot be read ({type(exc).__name__}: {exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{path}: no triangles in the file")
    faces = np.asarray(loaded.faces)
    n_vertices = len(loaded.vertices)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"{path}: faces of shape {faces.shape}, not triangles (a truncated or malformed file?)")
    if faces.min() < 0 or faces.max() >= n_vertices:
        raise MeshError(f"{path}: faces refer to vertices {int(faces.min())}..{int(faces.max())} of {n_vertices} "
                        "(a truncated or malformed file?)")
    # Drop visuals (uv seams duplicate vertices) and merge coincident vertices.
    mesh = trimesh.Trimesh(np.asarray(loaded.vertices, dtype=np.float64), faces.astype(np.int64), process=False)
    return mesh


def _clean(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    mesh = mesh.copy()
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.update_faces(mesh.nondegenerate_faces(height=1e-12))
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    return mesh


def repair_and_validate(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, list[str]]:
    """Repair what can be repaired and validate the rest.

    Checks, in order: finite coordinates, non-empty, one solid (multi-body meshes are fused with a boolean
    union, touching pieces included; stray open fragments under :data:`STRAY_AREA_FRACTION` of the area
    are dropped first), watertight (holes filled where possible), outward winding, positive
    volume.

    Args:
        mesh: a loaded mesh in any units.

    Returns:
        ``(mesh, repairs)``: the repaired mesh and the list of repairs applied (empty if none).

    Raises:
        MeshError: with the reason (e.g. ``"not watertight after repair (12 open edges)"``).
    """
    repairs: list[str] = []
    if not np.isfinite(mesh.vertices).all():
        raise MeshError("non-finite vertex coordinates")
    mesh = _clean(mesh)
    if len(mesh.faces) == 0:
        raise MeshError("empty mesh (no non-degenerate triangles)")

    bodies = mesh.split(only_watertight=False)
    if len(bodies) > 1:
        solids, n_stray, stray_area = [], 0, 0.0
        total_area = float(mesh.area)
        for body in bodies:
            if not body.is_watertight:
                trimesh.repair.fill_holes(body)
            if not body.is_watertight and body.area < STRAY_AREA_FRACTION * total_area:
                n_stray += 1
                stray_area += float(body.area)
                continue
            if not body.is_watertight:
                raise MeshError(f"{len(bodies)} bodies, one of them not watertight; cannot fuse them")
            trimesh.repair.fix_normals(body)
            solids.append(body)
        if n_stray:
            repairs.append(f"dropped {n_stray} stray open fragment{'s' if n_stray > 1 else ''} "
                           f"({100 * stray_area / total_area:.2g} % of the area)")
        if len(solids) == 1:
            mesh = solids[0]
        else:
            for body in solids:
                c = body.centroid
                body.vertices = c + (body.vertices - c) * TOUCH_INFLATION
            try:
                mesh = trimesh.boolean.union(solids, engine="manifold")
            except Exception as exc:
                raise MeshError(f"boolean union of {len(solids)} bodies failed ({exc})") from exc
            mesh = _clean(mesh)
            n_parts = len(mesh.split(only_watertight=False))
            if n_parts > 1:
                raise MeshError(f"disconnected: {n_parts} separate parts after fusing {len(solids)} bodies")
            repairs.append(f"fused {len(solids)} bodies")

    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
        if not mesh.is_watertight:
            n_open = int((np.bincount(mesh.edges_unique_inverse, minlength=len(mesh.edges_unique)) == 1).sum())
            raise MeshError(f"not watertight after repair ({n_open} open edges)")
        repairs.append("filled holes")
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
        repairs.append("fixed winding")
    if mesh.volume < 0:
        mesh.invert()
        repairs.append("inverted normals")
    if not mesh.is_volume:
        raise MeshError("not a valid volume (inconsistent winding or self-intersecting)")
    if not mesh.volume > 0:
        raise MeshError(f"non-positive volume ({mesh.volume:.3g})")
    return mesh, repairs


def choose_scale(extents: np.ndarray, longest: tuple[float, float], thickness: tuple[float, float],
                 rng: np.random.Generator) -> float:
    """Pick a uniform scale factor that makes the object graspable.

    The scale is drawn uniformly from the interval where the longest extent lies in ``longest`` and the
    smallest extent (the thickness a hand must close around) lies in ``thickness``.

    Args:
        extents: (3,) axis-aligned extents of the source mesh, any unit.
        longest: (min, max) longest extent after scaling, metres.
        thickness: (min, max) smallest extent after scaling, metres.
        rng: the generator the draw uses.

    Raises:
        MeshError: the two ranges admit no common scale (aspect ratio too extreme).
    """
    ext = np.sort(np.asarray(extents, dtype=np.float64))
    if ext[0] <= 0:
        raise MeshError(f"flat mesh (extents {ext.round(6).tolist()})")
    s_lo = max(longest[0] / ext[2], thickness[0] / ext[0])
    s_hi = min(longest[1] / ext[2], thickness[1] / ext[0])
    if s_lo > s_hi:
        raise MeshError(
            f"aspect ratio {ext[2] / ext[0]:.1f} cannot fit longest extent {longest} m with thickness {thickness} m")
    return float(rng.uniform(s_lo, s_hi))


def normalise(mesh: trimesh.Trimesh, scale: float) -> trimesh.Trimesh:
    """Scale ``mesh`` by ``scale`` and move its centre of mass to the origin (a copy)."""
    out = mesh.copy()
    out.apply_scale(scale)
    out.apply_translation(-out.center_mass)
    return out


def mass_properties(mesh: trimesh.Trimesh, density: float) -> MassProperties:
    """Volume, mass, centre of mass and inertia of a watertight mesh at ``density`` kg/m^3."""
    m = mesh.copy()
    m.density = density
    return MassProperties(volume=float(m.volume), mass=float(m.mass),
                          center_mass=np.asarray(m.center_mass, dtype=np.float64),
                          inertia=np.asarray(m.moment_inertia, dtype=np.float64))
