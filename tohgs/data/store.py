"""The Zarr v3 plumbing every tohgs store shares: atomic writes with ``dimension_names``, a schema and a
manifest, and a validating open that names the store and the problem.

Each store module (:mod:`tohgs.data.scenes`, :mod:`tohgs.data.grasps`, :mod:`tohgs.data.task_grasps`,
:mod:`tohgs.data.maps`, :mod:`tohgs.data.predictions`) defines its arrays and checks their shapes; this
module writes and reads them. A store of fixed arrays declares them once as a :class:`StoreLayout`.

**The manifest.** Zarr reads a chunk file that is missing (deleted, or a shard file cut to nothing) as the
array's fill value, silently. So every store records, as the last step inside its atomic write, a manifest
in the root attributes: per array its shape, dtype and the SHA-256 of its bytes (``arrays``), and the
SHA-256 of the other root attributes as written (``attributes``: the vocabularies, ``alpha_contact``, the
config a store was made with). A read checks the attributes and each array it returns against it, so a
missing or damaged chunk, or an edited attribute, fails with the store's and the array's name instead of
reading as zeros or as another store's vocabulary.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

MANIFEST = "manifest"
_RESERVED = ("schema", "schema_version", MANIFEST)


def array_digest(data: np.ndarray) -> str:
    """The SHA-256 (hex) of an array's C-ordered bytes (its shape and dtype are recorded beside it)."""
    return hashlib.sha256(np.ascontiguousarray(data).tobytes()).hexdigest()


def attrs_digest(attrs: dict[str, Any]) -> str:
    """The SHA-256 (hex) of root attributes as Zarr stores them (JSON), without the manifest: canonical JSON
    with sorted keys, so the digest depends on the values only."""
    body = {k: v for k, v in attrs.items() if k != MANIFEST}
    return hashlib.sha256(json.dumps(body, sort_keys=True, allow_nan=True).encode()).hexdigest()


def write_store(path: str | Path, arrays: dict[str, tuple[np.ndarray, tuple[str, ...]]], attrs: dict[str, Any],
                schema: str, version: int, shard_rows: int | None = None) -> None:
    """Write ``{name: (data, dimension_names)}`` and ``attrs`` (plus ``schema``, ``schema_version`` and the
    manifest) as a Zarr v3 group, atomically (temporary folder, then rename).

    With ``shard_rows``, every array uses the sharding codec: inner chunks of ``shard_rows`` rows along the
    first axis inside one shard file per array; otherwise one chunk per array.
    """
    import zarr

    from tohgs.io import atomic_dir

    clash = set(attrs) & set(_RESERVED)
    if clash:
        raise ValueError(f"{path}: attributes {sorted(clash)} are reserved for the store layer")
    manifest: dict[str, dict[str, Any]] = {}
    with atomic_dir(path) as tmp:
        root = zarr.open_group(str(tmp), mode="w", zarr_format=3)
        root.attrs.update({**attrs, "schema": schema, "schema_version": version})
        for name, (data, dims) in arrays.items():
            data = np.ascontiguousarray(data)
            if len(dims) != data.ndim:
                raise ValueError(f"{path}: array '{name}' has {data.ndim} dimensions but {len(dims)} names {dims}")
            if shard_rows is None:
                chunks, shards = tuple(max(1, s) for s in data.shape), None
            else:
                rows = max(1, min(shard_rows, len(data)))
                chunks = (rows, *(max(1, s) for s in data.shape[1:]))
                shards = (max(rows, -(-len(data) // rows) * rows), *chunks[1:])
            arr = root.create_array(name, shape=data.shape, dtype=data.dtype, chunks=chunks, shards=shards,
                                    dimension_names=dims)
            if data.size:
                arr[...] = data
            manifest[name] = {"shape": list(data.shape), "dtype": data.dtype.str, "sha256": array_digest(data)}
        stored = dict(zarr.open_group(str(tmp), mode="r").attrs)  # the attributes as written (JSON)
        root.attrs[MANIFEST] = {"arrays": manifest, "attributes": attrs_digest(stored)}  # last: else unfinished


def read_store(path: str | Path, schema: str, version: int, names: list[str] | None, kind: str,
               dims: dict[str, tuple[str, ...]] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Open a store and read ``names`` (None: every array of its manifest); ``(arrays, attrs)`` without the
    store layer's keys.

    Args:
        path: the store.
        schema, version: what the store must be.
        names: the arrays to read.
        kind: what the store should be, for messages ("map shard", ...).
        dims: optional ``{name: dimension_names}`` the arrays must have.

    Raises:
        ValueError: a missing store, not Zarr, another schema, another version, no manifest, a missing,
            unreadable or truncated array, or an array that does not match the manifest (a missing or
            damaged chunk). The message names the store and the array.
    """
    import zarr

    path = Path(path)
    if not path.is_dir():
        raise ValueError(f"{path}: {kind} not found")
    try:
        with warnings.catch_warnings():  # Snakemake's marker file in directory outputs is not Zarr
            warnings.filterwarnings("ignore", message=".*snakemake_timestamp")
            root = zarr.open_group(str(path), mode="r")
            present = set(root.array_keys())
    except Exception as exc:
        raise ValueError(f"{path}: not a Zarr store ({exc})") from exc
    attrs = dict(root.attrs)
    if attrs.get("schema") != schema:
        raise ValueError(f"{path}: not a tohgs {kind} (schema {attrs.get('schema')!r})")
    if attrs.get("schema_version") != version:
        raise ValueError(f"{path}: schema version {attrs.get('schema_version')}, this tohgs reads {version}")
    manifest = attrs.get(MANIFEST)
    if not isinstance(manifest, dict):
        raise ValueError(f"{path}: no manifest of its arrays (an unfinished write, or a store of an older tohgs); "
                         "rebuild it")
    if not isinstance(manifest.get("arrays"), dict) or "attributes" not in manifest:
        raise ValueError(f"{path}: its manifest does not cover the root attributes (a store of an older tohgs); "
                         "rebuild it")
    if attrs_digest(attrs) != manifest["attributes"]:
        raise ValueError(f"{path}: its root attributes (zarr.json) do not match their manifest checksum: edited or "
                         "damaged after the store was written; rebuild it")
    manifest = manifest["arrays"]
    arrays = {}
    for name in sorted(manifest) if names is None else names:
        if name not in present:
            raise ValueError(f"{path}: missing array '{name}'")
        if name not in manifest:
            raise ValueError(f"{path}: array '{name}' is not in the store's manifest")
        arr = root[name]
        if dims is not None and name in dims and tuple(arr.metadata.dimension_names or ()) != tuple(dims[name]):
            raise ValueError(f"{path}: array '{name}' has dimension_names {arr.metadata.dimension_names}, "
                             f"expected {tuple(dims[name])}")
        try:
            data = np.asarray(arr[...])
        except Exception as exc:
            raise ValueError(f"{path}: array '{name}' is unreadable or truncated ({exc})") from exc
        entry = manifest[name]
        if list(data.shape) != list(entry["shape"]) or data.dtype.str != entry["dtype"]:
            raise ValueError(f"{path}: array '{name}' is {data.dtype.str} {list(data.shape)}, its manifest says "
                             f"{entry['dtype']} {entry['shape']}")
        if array_digest(data) != entry["sha256"]:
            raise ValueError(f"{path}: array '{name}' does not match its manifest checksum: a chunk file is "
                             "missing or damaged (Zarr reads a missing chunk as fill values); rebuild the store")
        arrays[name] = data
    return arrays, {k: v for k, v in attrs.items() if k not in _RESERVED}


def check_shapes(arrays: dict[str, np.ndarray], expect: dict[str, tuple[int, ...]], source: str) -> None:
    """Every array named in ``expect`` has that shape; ``ValueError`` names ``source``, the array and both shapes."""
    for name, shape in expect.items():
        if arrays[name].shape != tuple(shape):
            raise ValueError(f"{source}: array '{name}' has shape {arrays[name].shape}, expected {tuple(shape)}")


@dataclass(frozen=True)
class StoreLayout:
    """A kind of store with fixed arrays: ``arrays`` maps each name to its ``(dimension_names, dtype)``;
    ``check(arrays, source)`` validates their shapes and values (raising ``ValueError``); ``kind`` names the
    store in messages. :meth:`write` casts, checks and writes; :meth:`read` reads and checks."""

    schema: str
    version: int
    kind: str
    arrays: dict[str, tuple[tuple[str, ...], Any]]
    check: Callable[[dict[str, np.ndarray], str], None]
    shard_rows: int | None = None

    def write(self, arrays: dict[str, np.ndarray], attrs: dict[str, Any], path: str | Path) -> None:
        """Write the store's arrays (cast to their dtypes) and ``attrs`` to ``path``, atomically."""
        cast = {k: np.asarray(arrays[k], dtype=dt) for k, (_, dt) in self.arrays.items()}
        self.check(cast, str(path))
        write_store(path, {k: (cast[k], dims) for k, (dims, _) in self.arrays.items()}, attrs, self.schema,
                    self.version, shard_rows=self.shard_rows)

    def read(self, path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Open and validate the store: ``(arrays, attrs)``; ``ValueError`` names the store and the problem."""
        arrays, attrs = read_store(path, self.schema, self.version, list(self.arrays), self.kind)
        self.check(arrays, str(path))
        return arrays, attrs
