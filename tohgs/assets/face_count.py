"""Counting the triangles of a mesh file without parsing it (:func:`tohgs.assets.mesh.count_faces`, which the
objects stage's face limit runs before trimesh reads the file): each counter follows what trimesh's reader of
the format (``trimesh/exchange/obj.py``, ``stl.py``, ``ply.py``) takes from a file, reading it a block at a
time, so memory does not grow with the file. Each returns ``(count, whole)``: ``whole`` is False where it
stopped early, above the caller's limit.
"""

from __future__ import annotations

import codecs
import math
import os
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import BinaryIO

import numpy as np

from tohgs.assets.mesh import MeshError
from tohgs.assets.sources import MESH_SUFFIXES


_READ_BLOCK = 1 << 18  # bytes read at a time
_PIECE = 1 << 16  # most characters of one line held at a time: a longer line is read in pieces
_PLY_HEADER_LINES = 10_000  # most lines of a PLY header
_PLY_HEADER_LINE_BYTES = 4096  # longest line of a PLY header
# str.splitlines' line boundaries: trimesh splits an ASCII PLY's body into records with it.
_LINE_ENDS = frozenset("\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029")
# PLY's types, as trimesh's PLY reader names them; the integer ones with their struct codes (list lengths).
_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "int8": "i1", "int16": "i2",
              "int32": "i4", "int64": "i8", "uint": "u4", "uint8": "u1", "uint16": "u2", "uint32": "u4",
              "uint64": "u8", "float": "f4", "float16": "f2", "float32": "f4", "float64": "f8", "double": "f8"}
_STRUCT_CODES = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "i8": "q", "u8": "Q"}


def count_triangles(path: Path, stop_above: int | None) -> tuple[int, bool]:
    """:func:`count_faces`' count, and whether it is the whole file's (False: it stopped above ``stop_above``)."""
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(f"{path}: unsupported suffix '{path.suffix}' (expected one of {MESH_SUFFIXES})")
    try:
        with open(path, "rb") as fh:
            if suffix == ".obj":
                return _count_text(path, fh, lambda texts: _count_obj(path, _obj_text(texts), stop_above))
            if suffix == ".stl":
                return _count_stl(path, fh, stop_above)
            return _count_ply(path, fh, stop_above)
    except OSError as exc:
        raise MeshError(f"{path}: cannot be read ({exc})") from exc


def _decoded(fh: BinaryIO, encoding: str, errors: str, start: int = 0) -> Iterator[str]:
    """The text of ``fh`` from byte ``start`` on, decoded a block at a time."""
    fh.seek(start)
    decoder = codecs.getincrementaldecoder(encoding)(errors=errors)
    while block := fh.read(_READ_BLOCK):
        if text := decoder.decode(block):
            yield text
    if text := decoder.decode(b"", final=True):
        yield text


def _count_text(path: Path, fh: BinaryIO, count: Callable[[Iterator[str]], tuple[int, bool]]) -> tuple[int, bool]:
    """``count`` (of the text's blocks) over a text file decoded as trimesh decodes an OBJ or an ASCII STL
    (``trimesh.util.decode_text``): UTF-8, or, for a file that is not, the encoding charset_normalizer guesses
    from its first 1000 bytes, dropping the bytes that do not decode."""
    try:
        return count(_decoded(fh, "utf-8", "strict"))
    except UnicodeDecodeError:
        pass
    fh.seek(0)
    head = fh.read(1000)
    try:
        from charset_normalizer import detect
    except ImportError as exc:
        raise MeshError(f"{path}: not UTF-8 text, and charset_normalizer, with which trimesh guesses the encoding "
                        "of such a file, is not installed") from exc
    encoding = detect(head)["encoding"] or "utf-8"
    try:
        codecs.getincrementaldecoder(encoding)
    except LookupError as exc:
        raise MeshError(f"{path}: not UTF-8 text, and the encoding guessed for it ({encoding!r}) is unknown") from exc
    return count(_decoded(fh, encoding, "ignore"))


def _line_pieces(texts: Iterable[str], universal: bool = False) -> Iterator[tuple[str, bool, bool] | None]:
    """The lines of a text given in blocks, split at ``\\n`` (``universal``: at :meth:`str.splitlines`'
    boundaries, which stay in the lines), as ``(piece, ends_line, cut_in_word)``: a line of more than
    :data:`_PIECE` characters comes in pieces, each cut after a space or tab where there is one
    (``cut_in_word``: there was none), so that memory stays bounded. None before each block but the first:
    more of the text follows (where a counter may stop)."""
    carry = ""
    for i, text in enumerate(texts):
        if i:
            yield None
        if carry:
            text = carry + text
        if not text:
            continue
        if universal:
            lines = text.splitlines(True)
            last = lines[-1][-1]
            carry = lines.pop() if last not in _LINE_ENDS or last == "\r" else ""  # a "\n" may follow a "\r"
        else:
            lines = text.split("\n")
            carry = lines.pop()
        for line in lines:
            yield line, True, False
        while len(carry) > _PIECE:
            cut = max(carry.rfind(" ", 0, _PIECE), carry.rfind("\t", 0, _PIECE)) + 1
            yield (carry[:cut], False, False) if cut else (carry[:_PIECE], False, True)
            carry = carry[cut or _PIECE:]
    if carry:
        yield carry, True, False


def _obj_text(texts: Iterable[str]) -> Iterator[str]:
    """An OBJ file's text as trimesh's OBJ reader reads it: ``\\r\\n`` as ``\\n``, then a backslash at the end of
    a line joins the next line to it (a backslash or ``\\r`` at a block's end waits for the next block; at the
    file's end trimesh drops them)."""
    carry = ""
    for text in texts:
        text = carry + text
        keep = 2 if text.endswith("\\\r") else 1 if text.endswith(("\\", "\r")) else 0
        carry = text[len(text) - keep:]
        yield text[:len(text) - keep].replace("\r\n", "\n").replace("\\\n", "")


def _count_obj(path: Path, text: Iterable[str], stop_above: int | None) -> tuple[int, bool]:
    """The triangles of an OBJ's face lines (:func:`count_faces`). trimesh reads the face lines of a group
    (faces of one material) as a table when they all have the same number of values (``1/2/3`` is three), each
    line with as many corners as the group's first line; otherwise a line of k corners is k - 2 triangles.
    So lines with the same number of values count as many triangles each as the one with the most corners."""
    widths: dict[int, list[int]] = {}  # values per line -> [face lines, most corners]
    total = 0
    state = 0  # 0: at a line's start (blanks so far), 1: in a face line, 2: in another line
    corners = values = 0  # of the face line so far
    in_corner = in_value = False  # whether the face line so far ends inside a corner / a value
    tail = ""  # its last characters: a "usemtl" across two pieces
    for item in _line_pieces(text):
        if item is None:
            so_far = total + (max(corners - 2, 0) if state == 1 else 0)  # a face line counts at least its own
            if stop_above is not None and so_far > stop_above:
                return so_far, False
            continue
        piece, ends, _ = item
        if state == 0:
            start = piece.lstrip()
            if start:
                if start[0] == "f":
                    state, piece, corners, values, in_corner, in_value, tail = 1, start[1:], 0, 0, False, False, ""
                else:
                    state = 2
        if state == 1 and piece:
            if "usemtl" in tail + piece:
                raise MeshError(f"{path}: a face line that holds 'usemtl' (trimesh would split it there): its "
                                "triangles cannot be counted reliably")
            tail = piece[-5:]
            numbers = piece.replace("/", " ")
            corners += len(piece.split()) - (in_corner and not piece[0].isspace())
            values += len(numbers.split()) - (in_value and not numbers[0].isspace())
            in_corner, in_value = not piece[-1].isspace(), not numbers[-1].isspace()
        if ends:
            if state == 1:
                width = widths.get(values)
                if width is None:
                    widths[values] = [1, corners]
                    total += max(corners - 2, 0)
                else:
                    lines, most = width
                    if corners > most:
                        total += lines * (max(corners - 2, 0) - max(most - 2, 0))
                        width[1] = most = corners
                    width[0] = lines + 1
                    total += max(most - 2, 0)
            state, corners = 0, 0
    return total, True


def _count_stl(path: Path, fh: BinaryIO, stop_above: int | None) -> tuple[int, bool]:
    """A binary STL's count (trimesh takes a file of 84 + 50 n bytes, n in its header, as binary), or an ASCII
    STL's (:func:`_count_stl_ascii`)."""
    head = fh.read(84)
    if len(head) == 84:
        n = int.from_bytes(head[80:84], "little")
        if 84 + 50 * n == os.fstat(fh.fileno()).st_size:
            return n, True
    return _count_text(path, fh, lambda texts: _count_stl_ascii(texts, stop_above))


def _count_stl_ascii(texts: Iterable[str], stop_above: int | None) -> tuple[int, bool]:
    """An ASCII STL's triangles as trimesh reads them: the numbers after each ``vertex`` (in any case), up to
    the next ``vertex`` or the line's end, are the vertices' coordinates, three vertices a triangle; so a line's
    values after its first ``vertex`` count, 9 a triangle (``facet`` lines do not count)."""
    n_values = 0
    in_vertex = False  # the line so far holds a "vertex"
    before = ""  # the end of the line's previous piece where it was cut inside a word (a "vertex" across two)
    for item in _line_pieces(texts):
        if item is None:
            if stop_above is not None and n_values // 9 > stop_above:
                return n_values // 9, False
            continue
        piece, ends, cut = item
        low = piece.lower()
        if not in_vertex:
            low = before + low
            at = low.find("vertex")
            in_vertex = at >= 0
            low = low[at:] if in_vertex else ""
        if low:  # a value cut in two counts twice: never fewer
            n_values += len(low.replace("vertex", " ").split())
        before = piece[-5:].lower() if cut else ""
        if ends:
            in_vertex = False
    return n_values // 9, True


@dataclass(frozen=True)
class _PlyProperty:
    """A property of a PLY element: ``code`` the numpy type code of a scalar or a list's items, ``count`` that of
    a list's length (None: a scalar)."""

    name: str
    code: str
    count: str | None = None

    @cached_property
    def size(self) -> int:
        return np.dtype(self.code).itemsize

    @cached_property
    def count_size(self) -> int:
        return np.dtype(self.count).itemsize if self.count else 0


@dataclass
class _PlyElement:
    name: str
    length: int
    properties: list[_PlyProperty] = field(default_factory=list)


def _ply_header(path: Path, fh: BinaryIO) -> tuple[str, list[_PlyElement]]:
    """The format (``ascii``, ``binary_little_endian``, ``binary_big_endian``) and the elements of a PLY
    header, read strictly, leaving ``fh`` at the body: trimesh takes its second line for the format, ends the
    header at the first line that holds ``end_header``, reads a first word that holds ``element`` or
    ``property`` as one, lets a repeated element or property replace the first, and ignores a property line it
    cannot read, so a header that is not plainly valid could be read otherwise than counted, and is refused."""

    def refused(line_no: int, why: str) -> MeshError:
        return MeshError(f"{path}: PLY header line {line_no}: {why}; the faces cannot be counted reliably")

    def words(line_no: int) -> list[str]:
        raw = fh.readline(_PLY_HEADER_LINE_BYTES + 1)
        if not raw:
            raise refused(line_no, "the file ends before 'end_header'")
        if len(raw) > _PLY_HEADER_LINE_BYTES:
            raise refused(line_no, f"longer than {_PLY_HEADER_LINE_BYTES} bytes")
        try:
            return raw.decode("utf-8").split()
        except UnicodeDecodeError:
            raise refused(line_no, "not UTF-8 text") from None

    if [w.lower() for w in words(1)] != ["ply"]:
        raise MeshError(f"{path}: not a PLY file (its first line is not 'ply')")
    line = words(2)
    formats = ("ascii", "binary_little_endian", "binary_big_endian")
    if len(line) != 3 or line[0] != "format" or line[1] not in formats:
        raise refused(2, f"{' '.join(line)!r} is not 'format <{'|'.join(formats)}> <version>'")
    fmt, elements = line[1], []
    for line_no in range(3, _PLY_HEADER_LINES + 1):
        line = words(line_no)
        shown = " ".join(line)
        if not line:
            raise refused(line_no, "an empty line")
        if "end_header" in line:
            if line != ["end_header"]:
                raise refused(line_no, f"{shown!r} holds 'end_header'")
            return fmt, elements
        key = line[0]
        if key == "element":
            if len(line) != 3 or not (line[2].isascii() and line[2].isdigit()):
                raise refused(line_no, f"{shown!r} is not 'element <name> <count>'")
            if any(e.name == line[1] for e in elements):
                raise refused(line_no, f"a second element '{line[1]}'")
            elements.append(_PlyElement(line[1], int(line[2])))
        elif key == "property":
            if not elements:
                raise refused(line_no, "a property before any element")
            if len(line) == 3 and line[1] in _PLY_TYPES:
                prop = _PlyProperty(line[2], _PLY_TYPES[line[1]])
            elif (len(line) == 5 and line[1] == "list" and _PLY_TYPES.get(line[2]) in _STRUCT_CODES
                  and line[3] in _PLY_TYPES):
                prop = _PlyProperty(line[4], _PLY_TYPES[line[3]], _PLY_TYPES[line[2]])
            else:
                raise refused(line_no, f"{shown!r} is not 'property <type> <name>' or 'property list <integer "
                                       "type> <type> <name>'")
            if any(p.name == prop.name for p in elements[-1].properties):
                raise refused(line_no, f"a second property '{prop.name}' of element '{elements[-1].name}'")
            elements[-1].properties.append(prop)
        elif key not in ("comment", "obj_info"):
            raise refused(line_no, f"unknown keyword {key!r}")
    raise MeshError(f"{path}: a PLY header of more than {_PLY_HEADER_LINES} lines; the faces cannot be counted "
                    "reliably")


def _count_ply(path: Path, fh: BinaryIO, stop_above: int | None) -> tuple[int, bool]:
    """The triangles of a PLY's ``face`` element (:func:`count_faces`)."""
    fmt, elements = _ply_header(path, fh)
    start = fh.tell()
    face_no = next((i for i, e in enumerate(elements) if e.name == "face"), None)
    if face_no is None or elements[face_no].length == 0:
        return 0, True
    face = elements[face_no]
    named = [i for i, p in enumerate(face.properties) if p.name in ("vertex_indices", "vertex_index")]
    if not named and len(face.properties) == 1:
        named = [0]  # trimesh's binary reader takes the only property of a face element, whatever its name
    if len(named) != 1 or face.properties[named[0]].count is None:
        why = ("both 'vertex_indices' and 'vertex_index'" if len(named) > 1 else
               "no 'vertex_indices' list property" if not named else f"'{face.properties[named[0]].name}' not a list")
        raise MeshError(f"{path}: the PLY face element has {why}; its triangles cannot be counted reliably")
    index = named[0]
    if fmt == "ascii":
        return _count_ply_ascii(path, fh, start, elements, face_no, index, stop_above)
    endian = ">" if fmt == "binary_big_endian" else "<"
    end = os.fstat(fh.fileno()).st_size
    theirs = _trimesh_binary_faces(fh, elements, face_no, index, endian, start, end)
    if theirs is not None and stop_above is not None and theirs > stop_above:
        return theirs, False
    body = _PlyBody(fh, start, end)
    try:
        for element in elements[:face_no]:
            _walk_ply_binary(path, body, element, endian, None, None, 0)
        total, stopped = _walk_ply_binary(path, body, face, endian, index, stop_above, 0)
    except _Truncated as exc:
        if theirs is None:
            raise MeshError(f"{path}: the PLY body ends inside {exc.where} (a truncated file?); the faces cannot be "
                            "counted reliably") from None
        return max(theirs, exc.total), True
    return max(total, theirs or 0), not stopped


def _ply_length(path: Path, text: str, row: int) -> int:
    """A list's length in an ASCII PLY face record (trimesh reads the number as a float and takes its int)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0 and value.is_integer()):
        raise MeshError(f"{path}: PLY face record {row}: a list length {text!r} that is not a non-negative integer; "
                        "the faces cannot be counted reliably")
    return int(value)


def _count_ply_ascii(path: Path, fh: BinaryIO, start: int, elements: list[_PlyElement], face_no: int, index: int,
                     stop_above: int | None) -> tuple[int, bool]:
    """The triangles of an ASCII PLY's face element. trimesh reads the body as UTF-8 text, one record a line
    (:meth:`str.splitlines`), the elements' records in order; a face record must hold its properties' values
    exactly (trimesh reads the lengths of a face element with one list, whose records are alike, from its first
    record): one that does not is refused."""
    face = elements[face_no]
    props = face.properties
    skip = sum(e.length for e in elements[:face_no])  # lines before the face element
    total = row = 0
    prop_no, left, corners = 0, 0, 0  # the record so far: next property, list values still to come, corners
    try:
        for item in _line_pieces(_decoded(fh, "utf-8", "strict", start), universal=True):
            if item is None:
                if stop_above is not None and total + max(corners - 2, 0) > stop_above:
                    return total + max(corners - 2, 0), False
                continue
            piece, ends, cut = item
            if skip:
                skip -= ends
                continue
            if cut:
                raise MeshError(f"{path}: PLY face record {row}: a value of more than {_PIECE} characters; the faces "
                                "cannot be counted reliably")
            tokens = piece.split()
            at = 0
            while at < len(tokens):
                if left:
                    take = min(left, len(tokens) - at)
                    at, left = at + take, left - take
                    continue
                if prop_no == len(props):
                    raise MeshError(f"{path}: PLY face record {row} holds more values than its properties; the faces "
                                    "cannot be counted reliably")
                prop = props[prop_no]
                prop_no, at = prop_no + 1, at + 1
                if prop.count is not None:
                    left = _ply_length(path, tokens[at - 1], row)
                    if prop_no - 1 == index:
                        corners = left
            if ends:
                if left or prop_no < len(props):
                    raise MeshError(f"{path}: PLY face record {row} holds fewer values than its properties; the faces "
                                    "cannot be counted reliably")
                total += max(corners - 2, 0)
                row, prop_no, corners = row + 1, 0, 0
                if row == face.length:
                    break
    except UnicodeDecodeError as exc:
        raise MeshError(f"{path}: the body of this ASCII PLY is not UTF-8 text ({exc.reason}), which trimesh cannot "
                        "read") from None
    return total, True


def _trimesh_binary_faces(fh: BinaryIO, elements: list[_PlyElement], face_no: int, index: int, endian: str,
                          start: int, end: int) -> int | None:
    """The triangles trimesh's binary PLY reader takes from a body: it reads each list's length in the first
    record of its element, takes every record of the element to be as long, and refuses a file whose size then
    differs from the elements' (None: it refuses the file or takes no faces)."""
    pos, first = start, 0
    for element_no, element in enumerate(elements):
        size = 0
        for prop_no, prop in enumerate(element.properties):
            if prop.count is None:
                size += prop.size
                continue
            fh.seek(pos + size)
            blob = fh.read(prop.count_size)
            if not blob and element_no > face_no:  # trimesh drops a property it cannot read after the faces
                return elements[face_no].length * max(first - 2, 0)
            if len(blob) < prop.count_size:
                return None
            n = int(np.frombuffer(blob, endian + prop.count)[0])
            if n < 0:
                return None
            if element_no == face_no and prop_no == index:
                first = n
            size += prop.count_size + n * prop.size
        pos += element.length * size
    return elements[face_no].length * max(first - 2, 0) if pos == end else None


class _Truncated(Exception):
    """A binary PLY body that ends inside a record; ``total``: the triangles counted before."""

    def __init__(self, where: str, total: int) -> None:
        super().__init__(where)
        self.where, self.total = where, total


class _PlyBody:
    """A binary PLY body read forward a block at a time: ``data[at:]`` holds the bytes from file position
    ``pos`` on; ``end`` is the file's size."""

    def __init__(self, fh: BinaryIO, start: int, end: int) -> None:
        self.fh, self.pos, self.end, self.data, self.at = fh, start, end, b"", 0

    def hold(self, n: int) -> int:
        """Hold the next ``n`` bytes (fewer at the file's end); returns how many are held."""
        held = len(self.data) - self.at
        if held < n:
            self.fh.seek(self.pos + held)
            self.data = self.data[self.at:] + self.fh.read(max(n - held, _READ_BLOCK))
            self.at, held = 0, len(self.data)
        return min(held, n)

    def read(self, offset: int, n: int) -> bytes:
        """``n`` bytes from ``offset`` bytes past the position (fewer at the file's end), without holding more than
        a few blocks."""
        if offset + n > len(self.data) - self.at and offset + n <= 4 * _READ_BLOCK:
            self.hold(offset + n)
        if offset + n <= len(self.data) - self.at:
            return self.data[self.at + offset:self.at + offset + n]
        self.fh.seek(self.pos + offset)
        return self.fh.read(n)

    def skip(self, n: int) -> None:
        held = len(self.data) - self.at
        if n <= held:
            self.at += n
        else:
            self.data, self.at = b"", 0
        self.pos += n


def _ply_record(path: Path, body: _PlyBody, element: _PlyElement, endian: str, row: int
                ) -> tuple[list[int], list[int], int]:
    """The list lengths, their offsets and the size in bytes of the binary record at the body's position."""
    size, lengths, offsets = 0, [], []
    for prop in element.properties:
        if prop.count is not None:
            blob = body.read(size, prop.count_size)
            if len(blob) < prop.count_size:
                break
            n = struct.unpack(endian + _STRUCT_CODES[prop.count], blob)[0]
            if n < 0:
                raise MeshError(f"{path}: PLY element '{element.name}' record {row}: a list of length {n}; the faces "
                                "cannot be counted reliably")
            lengths.append(n)
            offsets.append(size)
            size += prop.count_size + n * prop.size
        else:
            size += prop.size
    else:
        if body.pos + size <= body.end:
            return lengths, offsets, size
    raise _Truncated(f"record {row} of element '{element.name}'", 0)


def _walk_ply_binary(path: Path, body: _PlyBody, element: _PlyElement, endian: str, index: int | None,
                     stop_above: int | None, total: int) -> tuple[int, bool]:
    """Walk over a binary element's records from the body's position: ``total`` plus the triangles of the list
    property ``index`` (None: none), and whether the walk stopped early (the total above ``stop_above``).
    Records laid out as the one before them (lists of the same lengths) are checked in numpy blocks."""
    props = element.properties
    if all(p.count is None for p in props):
        n = element.length * sum(p.size for p in props)
        if body.pos + n > body.end:
            raise _Truncated(f"element '{element.name}' ({element.length} records of {n // element.length} bytes)",
                             total)
        body.skip(n)
        return total, False
    which = sum(p.count is not None for p in props[:index]) if index is not None else None
    left, row, batch, one_by_one = element.length, 0, 64, 0
    while left:
        try:
            lengths, offsets, size = _ply_record(path, body, element, endian, row)
        except _Truncated as exc:
            raise _Truncated(exc.where, total) from None
        run = 1
        if one_by_one:
            one_by_one -= 1
        elif left > 1 and size <= _READ_BLOCK:
            wanted = min(left, batch, _READ_BLOCK // size)
            held = body.hold(wanted * size) // size
            if held > 1:
                layout = np.dtype({"names": [f"n{j}" for j in range(len(lengths))],
                                   "formats": [endian + p.count for p in props if p.count is not None],
                                   "offsets": offsets, "itemsize": size})
                records = np.frombuffer(body.data, layout, held, body.at)
                alike = np.ones(held, dtype=bool)
                for j, n in enumerate(lengths):
                    alike &= records[f"n{j}"] == n
                run = held if alike.all() else int(alike.argmin())
            if run == wanted:
                batch = min(2 * batch, 1 << 16)
            elif run < 8:  # lengths that change often: read record by record for a while
                batch, one_by_one = 64, 256
        if which is not None:
            total += run * max(lengths[which] - 2, 0)
        body.skip(run * size)
        left, row = left - run, row + run
        if stop_above is not None and total > stop_above and left:
            return total, True
    return total, False
