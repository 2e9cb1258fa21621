"""Checksums of the files of an object's folder of the objects stage (``results/objects/<name>/``), the same idea
as the stores' manifest (:mod:`tohgs.data.store`).

A mesh file cut at a line boundary still parses: trimesh reads the faces that are left, PyBullet the convex
parts that are left, and every metric downstream changes without a word. So the stage that writes a folder
(:func:`tohgs.assets.objects.prepare_object`, the official importer) records in its ``meta.json``, under
``files``, per file its SHA-256, its size in bytes and, for a mesh, its face count as :func:`trimesh.load`
reads it; every reader checks the file it reads against that record first (:func:`check_object_file`), and a
mesh reader compares the faces it loaded (:func:`check_faces`).

Cheap: a file's digest is computed once per process (keyed by its path, inode, size and modification time,
so a file changed in place is hashed again), and ``meta.json`` is parsed once per version.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from tohgs.io import file_sha256, stat_key

#: The key of ``meta.json`` that holds the folder's file records.
FILES_KEY = "files"
#: The folder's record, written by the stage that writes the folder.
META_JSON = "meta.json"

_METAS: dict[tuple[str, int, int, int, int], dict[str, Any]] = {}


def _count_faces(path: Path) -> int:
    """The faces of a mesh file as the readers load it (``trimesh.load(force="mesh", process=False)``)."""
    import trimesh

    return int(len(trimesh.load(path, force="mesh", process=False).faces))


def file_records(folder: str | Path, names: list[str] | tuple[str, ...]) -> dict[str, dict[str, Any]]:
    """``{name: {"sha256", "bytes"[, "faces"]}}`` of the files ``names`` of ``folder`` (faces for ``.obj``)."""
    folder = Path(folder)
    records: dict[str, dict[str, Any]] = {}
    for name in names:
        path = folder / name
        record: dict[str, Any] = {"sha256": file_sha256(path), "bytes": path.stat().st_size}
        if path.suffix == ".obj":
            record["faces"] = _count_faces(path)
        records[name] = record
    return records


def record_object_files(folder: str | Path, meta: dict[str, Any], names: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """Add the records of ``folder``'s files ``names`` to ``meta`` (under :data:`FILES_KEY`) and write it as the
    folder's ``meta.json`` (atomically); the last step of writing a folder. Returns ``meta``."""
    from tohgs.io import write_json

    meta[FILES_KEY] = file_records(folder, names)
    write_json(Path(folder) / META_JSON, meta)
    return meta


def read_meta(meta_path: str | Path) -> dict[str, Any]:
    """A folder's ``meta.json``, parsed once per version, its recorded name checked against the folder's
    (:func:`check_meta_name`); ``ValueError`` naming the file otherwise."""
    meta_path = Path(meta_path)
    meta = _read_meta(meta_path)
    check_meta_name(meta, meta_path.parent)
    return meta


def _read_meta(meta_path: Path) -> dict[str, Any]:
    """A folder's ``meta.json``, parsed once per version (``ValueError`` naming an unreadable one)."""
    key = stat_key(meta_path)
    if key not in _METAS:
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{meta_path}: unreadable ({exc}); rerun the objects stage for "
                             f"'{meta_path.parent.name}'") from exc
        if not isinstance(meta, dict):
            raise ValueError(f"{meta_path}: not a mapping; rerun the objects stage for '{meta_path.parent.name}'")
        _METAS[key] = meta
    return _METAS[key]


def check_meta_name(meta: dict[str, Any], folder: str | Path) -> None:
    """The object a folder's ``meta.json`` records is the folder's own: a folder copied over another's
    (``cp -a results/objects/a results/objects/b``) carries files whose checksums all match, and only the
    recorded name tells it is the wrong object.

    Raises:
        ValueError: the recorded ``name`` is not the folder's name; the message names both.
    """
    folder = Path(folder)
    name = meta.get("name")
    if name is not None and name != folder.name:
        raise ValueError(f"{folder / META_JSON}: records the object '{name}', but its folder is '{folder.name}' "
                         f"(a folder copied or renamed over another's); rerun the objects stage for "
                         f"'{folder.name}' (delete the folder)")


def _records(folder: Path, subject: str) -> dict[str, dict[str, Any]]:
    """The file records of an objects ``folder``'s ``meta.json``; ``ValueError`` starting with ``subject``
    where it has none (no ``meta.json``: not a folder of the objects stage, or an unfinished one; no records:
    a folder of an older tohgs)."""
    meta_path = folder / META_JSON
    rerun = f"rerun the objects stage for '{folder.name}' (delete the folder)"
    if not meta_path.is_file():
        raise ValueError(f"{subject}no {META_JSON} in its folder, so nothing to check it against (not a folder of "
                         f"the objects stage, or an unfinished one); {rerun}")
    meta = _read_meta(meta_path)
    check_meta_name(meta, folder)
    records = meta.get(FILES_KEY)
    if not isinstance(records, dict):
        raise ValueError(f"{subject}{meta_path} records no checksums of the folder's files (a folder of an older "
                         f"tohgs); {rerun}")
    return records


def check_object_file(path: str | Path) -> dict[str, Any]:
    """Check one file of an objects folder against the record in the folder's ``meta.json``; returns the record.

    Raises:
        ValueError: the file is missing, the folder has no ``meta.json`` or no records (a folder of an
            older tohgs, or not of the objects stage), the file has no record, or its size or SHA-256 differ
            from the record (damaged or changed after the stage wrote it). The message names the file.
    """
    path = Path(path)
    folder = path.parent
    meta_path = folder / META_JSON
    rerun = f"rerun the objects stage for '{folder.name}' (delete the folder)"
    if not path.is_file():
        raise ValueError(f"{path}: missing from the object's folder; {rerun}")
    records = _records(folder, f"{path}: ")
    record = records.get(path.name)
    if not isinstance(record, dict) or "sha256" not in record:
        raise ValueError(f"{path}: not among the files {meta_path} records ({', '.join(sorted(records))}); {rerun}")
    size = path.stat().st_size
    if size != record.get("bytes", size) or file_sha256(path) != record["sha256"]:
        raise ValueError(f"{path}: does not match the checksum in {meta_path} ({size} bytes, {record.get('bytes')} "
                         f"recorded): the file was damaged or changed after the objects stage wrote it; {rerun}")
    return record


def check_faces(path: str | Path, n_faces: int, record: dict[str, Any]) -> None:
    """A mesh loaded from ``path`` with ``n_faces`` faces has at least the faces its ``record`` holds.

    Raises:
        ValueError: fewer faces than recorded (a truncated or damaged file); the message names the file.
    """
    want = record.get("faces")
    if want is not None and n_faces < int(want):
        raise ValueError(f"{path}: loads with {n_faces} faces, its objects stage recorded {want}: a truncated or "
                         f"damaged file; rerun the objects stage for '{Path(path).parent.name}' (delete the folder)")


def check_object_folder(folder: str | Path) -> None:
    """Check every file the folder's ``meta.json`` records (:func:`check_object_file`)."""
    folder = Path(folder)
    records = _records(folder, f"{folder}: ")
    for name in sorted(records):
        check_object_file(folder / name)


def check_object_urdf(urdf: str | Path) -> Path:
    """Check an object's URDF and the files of its folder it names (its mesh and collision parts) against
    their records before a simulator loads them (:func:`check_object_folder`); returns ``urdf``."""
    urdf = Path(urdf)
    check_object_file(urdf)
    check_object_folder(urdf.parent)
    return urdf
