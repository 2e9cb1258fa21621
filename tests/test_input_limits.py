"""Input that once got past a limit (the issue "Robustness: the mesh face limit can be bypassed"): valid mesh
encodings whose triangles :func:`~tohgs.assets.mesh.count_faces` undercounted while trimesh parsed them all (OBJ
face lines continued over a line break, upper-case ASCII STL, PLY polygons), and the official importer, which
held a whole mesh file in memory to hash it before the size limit could refuse it, and imported a grasp file
listed in both ``train.txt`` and ``val.txt`` as val without a word."""

from __future__ import annotations

import hashlib
import json
import re
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import trimesh

from tohgs.assets.mesh import MeshError, MeshLimits, check_mesh_limits, count_faces

# ---------------------------------------------------------------------------------------------------------
# The face count is never below what trimesh parses, and check_mesh_limits refuses the file naming it.


def _parsed(path: Path) -> int:
    """The triangles trimesh takes from the file, read as load_mesh reads it."""
    return len(trimesh.load(str(path), force="mesh", process=False).faces)


def _counted_and_refused(path: Path, exact: bool = True) -> int:
    """Assert that the file's count is what trimesh parses (``exact``; else at least that), that the count is
    within a limit of itself and that a limit below what trimesh parses refuses the file, naming it."""
    parsed, n = _parsed(path), count_faces(path)
    assert (n == parsed) if exact else (n >= parsed), (n, parsed)
    assert check_mesh_limits(path, MeshLimits(max_faces=n)) == n
    with pytest.raises(MeshError, match=rf"^{re.escape(str(path))}: (at least )?\d+ faces, more than "
                                        rf"objects\.limits\.max_faces = {parsed - 1} "):
        check_mesh_limits(path, MeshLimits(max_faces=parsed - 1))
    return n


def _sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3)  # 642 vertices, 1280 triangles


def _obj(mesh: trimesh.Trimesh, face: str, newline: str = "\n") -> str:
    """An OBJ of ``mesh`` with each face written as ``face.format(a, b, c)`` (1-based corners)."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}{newline}" for x, y, z in mesh.vertices]
    return "".join(lines) + "".join(face.format(a + 1, b + 1, c + 1) for a, b, c in mesh.faces)


OBJ_FACES = {  # case: (face line, vertex line end)
    "continued": ("f\\\n {} {} {}\n", "\n"),  # QA's file: counted 0, parsed in full
    "continued within the face": ("f {} {}\\\n {}\n", "\n"),
    "continued, CRLF": ("f\\\r\n {} {} {}\r\n", "\r\n"),
    "tabs": ("f\t{}\t{}\t{}\n", "\n"),
}


@pytest.mark.parametrize("case", OBJ_FACES)
def test_obj_faces_in_every_syntax_trimesh_reads_are_counted(tmp_path, case):
    face, newline = OBJ_FACES[case]
    sphere = _sphere()
    path = tmp_path / "sphere.obj"
    text = _obj(sphere, face, newline)
    if case == "tabs":  # trimesh takes "f\t" lines between "f " lines: the first and the last face with a space
        text = re.sub(r"^f\t(.*)\t(.*)\t(.*)$", r"f \1 \2 \3", text, count=1, flags=re.MULTILINE)
        text = text[:text.rindex("f\t")] + "f " + text[text.rindex("f\t") + 2:]
    path.write_text(text, newline="")
    assert _counted_and_refused(path) == 1280


def test_obj_face_lines_of_equal_width_count_as_many_corners_as_the_widest(tmp_path):
    """trimesh reads face lines with as many values each (``1 2 3 4 5 6``, ``1/1 2/2 3/3``) as one table, every
    line with the corners of the first: a hexagon first makes each later triangle 4 triangles."""
    sphere = _sphere()
    path = tmp_path / "wide.obj"
    path.write_text(_obj(sphere, "f {0}/{0} {1}/{1} {2}/{2}\n").replace("\nf ", "\nf 1 2 3 4 5 6\nf ", 1))
    assert _counted_and_refused(path) == 4 * 1281


def test_a_utf16_obj_is_counted_as_trimesh_decodes_it(tmp_path):
    path = tmp_path / "utf16.obj"
    path.write_bytes(_obj(_sphere(), "f {} {} {}\n").encode("utf-16"))  # with a byte order mark
    assert _counted_and_refused(path) == 1280


def _ascii_stl(mesh: trimesh.Trimesh) -> str:
    return trimesh.exchange.stl.export_stl_ascii(mesh)


@pytest.mark.parametrize("case", ["upper case", "upper case, tabs and CRLF", "mixed case", "vertex lines only"])
def test_ascii_stl_in_any_case_is_counted(tmp_path, case):
    sphere = _sphere()
    text = {"upper case": lambda: _ascii_stl(sphere).upper(),
            "upper case, tabs and CRLF": lambda: _ascii_stl(sphere).upper().replace(" ", "\t").replace("\n", "\r\n"),
            "mixed case": lambda: _ascii_stl(sphere).replace("facet", "FaCeT").replace("vertex", "VeRtEx"),
            # trimesh takes the numbers after each "vertex", not facets: nine numbers a triangle
            "vertex lines only": lambda: "solid s\n" + "".join(
                "vertex " + " ".join(f"{c:.7g}" for c in tri.ravel()) + "\n" for tri in sphere.triangles)
            + "endsolid s\n"}[case]()
    path = tmp_path / "sphere.stl"
    path.write_bytes(text.encode())
    assert _counted_and_refused(path) == 1280


def _polygons(n: int, k: int, n_vertices: int) -> list[list[int]]:
    return [[(7 * i + j) % n_vertices for j in range(k)] for i in range(n)]


def _ply(path: Path, fmt: str, vertices: np.ndarray, polygons: list[list[int]], vertex_list: bool = False,
         face_extras: bool = False) -> Path:
    """A PLY of ``vertices`` and ``polygons`` (``vertex_list``: each vertex with a list property of two floats;
    ``face_extras``: each face with a uchar before its corners and a float after)."""
    e = ">" if fmt == "binary_big_endian" else "<"
    header = ["ply", f"format {fmt} 1.0", f"element vertex {len(vertices)}", "property float x", "property float y",
              "property float z", *(["property list uchar float texcoord"] if vertex_list else []),
              f"element face {len(polygons)}", *(["property uchar flags"] if face_extras else []),
              "property list ushort int vertex_indices", *(["property float quality"] if face_extras else []),
              "end_header"]
    if fmt == "ascii":
        rows = [" ".join(f"{c:.7g}" for c in v) + (" 2 0.25 0.5" if vertex_list else "") for v in vertices]
        rows += [("1 " if face_extras else "") + " ".join(map(str, [len(p), *p])) + (" 0.5" if face_extras else "")
                 for p in polygons]
        body = ("\n".join(rows) + "\n").encode()
    else:
        texcoord = b"\x02" + np.array([0.25, 0.5], e + "f4").tobytes() if vertex_list else b""
        body = b"".join(np.asarray(v, e + "f4").tobytes() + texcoord for v in vertices)
        body += b"".join((b"\x01" if face_extras else b"") + np.array([len(p)], e + "u2").tobytes()
                         + np.asarray(p, e + "i4").tobytes() + (np.array([0.5], e + "f4").tobytes() if face_extras
                                                                else b"") for p in polygons)
    path.write_bytes(("\n".join(header) + "\n").encode() + body)
    return path


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_polygons_count_as_the_triangles_trimesh_makes_of_them(tmp_path, fmt):
    """QA's file: the header said 319 faces, each a polygon of 319 corners, which trimesh made 101,125 triangles
    (the same, smaller: 20 polygons of 100 corners, 1960 triangles; 60 of 12, 600)."""
    vertices = _sphere().vertices
    assert _counted_and_refused(_ply(tmp_path / "big.ply", fmt, vertices, _polygons(20, 100, 642))) == 20 * 98
    assert _counted_and_refused(_ply(tmp_path / "p12.ply", fmt, vertices, _polygons(60, 12, 642))) == 60 * 10


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_with_a_vertex_list_property_and_face_properties_is_counted(tmp_path, fmt):
    vertices = _sphere().vertices
    path = _ply(tmp_path / "lists.ply", fmt, vertices, _polygons(50, 9, 642), vertex_list=True, face_extras=True)
    assert _counted_and_refused(path) == 50 * 7


def test_ply_records_of_different_lengths_are_counted_one_by_one(tmp_path):
    """Triangles, quads and polygons mixed: trimesh reads an ASCII file line by line; a binary one it cannot
    read (it takes every record to be as long as the first), and the count is the records' sum."""
    vertices = _sphere().vertices
    polygons = [p for i in range(300) for p in _polygons(1, 3 + i % 5, 642)]
    expected = sum(len(p) - 2 for p in polygons)
    assert _counted_and_refused(_ply(tmp_path / "mixed.ply", "ascii", vertices, polygons)) == expected
    binary = _ply(tmp_path / "mixed-bin.ply", "binary_little_endian", vertices, polygons)
    with pytest.raises(ValueError, match="unexpected length"):
        _parsed(binary)
    assert count_faces(binary) == expected


def test_a_binary_ply_counts_what_trimesh_reads_where_it_reads_more_than_the_records_hold(tmp_path):
    """trimesh takes every face record of a binary PLY to be as long as the first: a first record of 100 corners
    followed by records of 3 whose bytes add up to 100-corner records is read as 100-gons."""
    vertices = _sphere().vertices
    first, n = _polygons(1, 100, 642), 10
    record = 2 + 4 * 100  # ushort count, 100 int corners
    triangle = 2 + 4 * 3
    fill = (n - 1) * record // triangle  # triangles after the first record, then padding in a last one
    polygons = first + _polygons(fill, 3, 642)
    spare = (n - 1) * record - fill * triangle
    polygons.append(list(range((spare - 2) // 4)))  # the last record fills the rest
    path = _ply(tmp_path / "liar.ply", "binary_little_endian", vertices, polygons)
    text = path.read_bytes().replace(f"element face {len(polygons)}".encode(), f"element face {n}".encode(), 1)
    path.write_bytes(text)
    assert _parsed(path) == n * 98
    assert count_faces(path) == n * 98


@pytest.mark.parametrize(("case", "header", "why"), [
    ("a comment before the format", "ply\ncomment made by hand\nformat ascii 1.0\n",
     "line 2: 'comment made by hand' is not 'format"),
    ("a repeated property", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float x\n",
     "line 5: a second property 'x' of element 'vertex'"),
    ("end_header in a comment", "ply\nformat ascii 1.0\ncomment no end_header here\n",
     "line 3: 'comment no end_header here' holds 'end_header'"),
    ("an unknown keyword", "ply\nformat ascii 1.0\nelements vertex 3\n", "line 3: unknown keyword 'elements'"),
    ("both index lists", "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
                         "property list uchar int vertex_index\nend_header\n3 0 1 2 3 0 1 2\n",
     "the PLY face element has both 'vertex_indices' and 'vertex_index'"),
    ("a face record with a value too many", "ply\nformat ascii 1.0\nelement face 1\n"
                                            "property list uchar int vertex_indices\nend_header\n3 0 1 2 7\n",
     "PLY face record 0 holds more values than its properties"),
])
def test_a_ply_that_cannot_be_counted_reliably_is_refused_naming_it(tmp_path, case, header, why):
    path = tmp_path / "bad.ply"
    path.write_text(header + ("element vertex 0\nend_header\n" if "end_header" not in header else ""))
    with pytest.raises(MeshError, match=rf"^{re.escape(str(path))}: .*{re.escape(why)}"):
        count_faces(path)


def test_a_truncated_binary_ply_is_refused_naming_it(tmp_path):
    polygons = _polygons(40, 7, 642)
    path = _ply(tmp_path / "cut.ply", "binary_little_endian", _sphere().vertices, polygons)
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(MeshError, match=rf"^{re.escape(str(path))}: the PLY body ends inside record 39 of element "
                                        r"'face' \(a truncated file\?\)"):
        count_faces(path)


# ---------------------------------------------------------------------------------------------------------
# The count stops once it exceeds the limit, and its memory does not grow with the file.


def test_the_count_stops_once_it_exceeds_the_limit(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=6)  # 81,920 triangles
    obj = tmp_path / "big.obj"
    obj.write_text(_obj(sphere, "f {} {} {}\n"))
    polygons = [p for i in range(60_000) for p in _polygons(1, 3 + i % 2, len(sphere.vertices))]
    ply = _ply(tmp_path / "big.ply", "binary_little_endian", sphere.vertices, polygons)  # a triangle, a quad, ...
    for path, whole in ((obj, 81_920), (ply, 90_000)):
        assert count_faces(path) == whole
        early = count_faces(path, stop_above=1000)
        assert 1000 < early < whole / 2, (path.name, early)
        with pytest.raises(MeshError, match=rf"^{re.escape(str(path))}: at least \d+ faces, more than "
                                            r"objects\.limits\.max_faces = 1000 "):
            check_mesh_limits(path, MeshLimits(max_faces=1000))


def test_the_count_holds_a_few_blocks_of_the_file_whatever_its_lines(tmp_path):
    """A face line of a million corners (14 MB) was read whole, and split into a million words."""
    path = tmp_path / "one-line.obj"
    with open(path, "w") as fh:
        fh.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nf")
        for _ in range(1000):
            fh.write(" 1000000000001" * 1000)
        fh.write("\n")
    size = path.stat().st_size
    tracemalloc.start()
    try:
        n = count_faces(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert n == 1000 * 1000 - 2
    assert peak < 6e6 < size, f"{peak / 1e6:.1f} MB traced counting a {size / 1e6:.1f} MB file"


# ---------------------------------------------------------------------------------------------------------
# The official importer: a mesh is hashed a block at a time; a grasp file in both lists is a problem.


def test_the_importer_hashes_a_mesh_a_block_at_a_time(tmp_path, monkeypatch):
    """A 419 MB mesh once took 400 MB more to be hashed (read whole) before load_mesh's size limit refused it."""
    from tohgs.assets.decomposition import DecompositionSettings
    from tohgs.official.importer import _import_object, _Reader

    rel = "models/meshdata/huge/coacd/decomposed_scaled.obj"
    path = tmp_path / "official" / rel
    path.parent.mkdir(parents=True)
    with open(path, "w") as fh:
        fh.write(_obj(trimesh.creation.box(extents=(0.05, 0.05, 0.05)), "f {} {} {}\n"))
        line = "# " + "padding " * 1000 + "\n"
        for _ in range(50_000_000 // len(line)):
            fh.write(line)
    size = path.stat().st_size
    expected = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            expected.update(block)

    def whole(self, *a, **k):
        raise AssertionError(f"{self} read whole")

    monkeypatch.setattr(Path, "read_bytes", whole)
    reader = _Reader(tmp_path / "official")
    tracemalloc.start()
    try:
        assert reader.hash(rel) == path
        meta = _import_object(reader, "huge", False, tmp_path / "out", 500.0, DecompositionSettings(), None,
                              MeshLimits(max_file_mb=10.0))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert reader.digests[rel] == expected.hexdigest()
    assert meta["status"] == "rejected" and "larger than objects.limits.max_file_mb = 10 MB" in meta["reason"]
    assert peak < 5e6 < size, f"{peak / 1e6:.1f} MB traced hashing a {size / 1e6:.0f} MB file"


def test_a_grasp_file_in_both_train_and_val_is_a_problem_imported_in_neither_split(tmp_path):
    from synthetic_official import DS, make_official_tree

    from tohgs.hand import load_hand_assets
    from tohgs.official.importer import import_official

    tree = make_official_tree(tmp_path / "official")
    (tree["root"] / DS / "placing/val.txt").write_text("can_b.npy\nmug_a.npy\n")  # mug_a.npy is in train.txt too
    report = import_official(tree["root"], tmp_path / "out", load_hand_assets("anny"), ["placing"])
    problems = [p for p in report.problems if p["kind"] == "split"]
    assert problems == [{"path": f"{DS}/placing/val.txt", "kind": "split", "reason": (
        f"'mug_a.npy' is listed in both {DS}/placing/train.txt and {DS}/placing/val.txt: imported in neither split "
        "(neither its grasps nor its test configurations)")}]
    assert report.splits["placing"] == {"train": [], "val": ["off-can-b"], "test": ["off-can-b"]}
    assert report.tasks["placing"]["files"] == 1  # can_b.npy (broken.npy is unreadable)
    assert not (tmp_path / "out/scenes/placing/off-mug-a.zarr").exists()
    assert not (tmp_path / "out/grasps/task/placing/off-mug-a.zarr").exists()
    assert not any("mug_a" in note for note in report.notes)  # not "in no split": a problem
    written = json.loads((tmp_path / "out/import_report.json").read_text())
    assert [p for p in written["problems"] if p["kind"] == "split"] == problems
