"""The Zarr v3 plumbing every tohgs store shares: atomic writes with ``dimension_names`` and a schema,
and a validating open that names the store and the problem.

Each store module (:mod:`tohgs.data.task_grasps`, :mod:`tohgs.data.maps`, :mod:`tohgs.data.predictions`)
defines its arrays and checks their shapes; this module writes and reads them.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np


def write_store(path: str | Path, arrays: dict[str, tuple[np.ndarray, tuple[str, ...]]], attrs: dict[str, Any],
                schema: str, version: int, shard_rows: int | None = None) -> None:
    """Write ``{name: (data, dimension_names)}`` and ``attrs`` (plus ``schema`` and ``schema_version``) as a
    Zarr v3 group, atomically (temporary folder, then rename).

    With ``shard_rows``, every array uses the sharding codec: inner chunks of ``shard_rows`` rows along the
    first axis inside one shard file per array; otherwise one chunk per array.
    """
    import zarr

    from tohgs.io import atomic_dir

    with atomic_dir(path) as tmp:
        root = zarr.open_group(str(tmp), mode="w", zarr_format=3)
        root.attrs.update({**attrs, "schema": schema, "schema_version": version})
        for name, (data, dims) in arrays.items():
            data = np.ascontiguousarray(data)
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


def read_store(path: str | Path, schema: str, version: int, names: list[str], kind: str
               ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Open a store and read ``names``; ``(arrays, attrs)`` without the schema keys.

    Raises:
        ValueError: a missing store, not Zarr, another schema, another version, a missing, unreadable or
            truncated array. The message names the store (``kind`` says what it should be).
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
    arrays = {}
    for name in names:
        if name not in present:
            raise ValueError(f"{path}: missing array '{name}'")
        try:
            arrays[name] = np.asarray(root[name][...])
        except Exception as exc:
            raise ValueError(f"{path}: array '{name}' is unreadable or truncated ({exc})") from exc
    return arrays, {k: v for k, v in attrs.items() if k not in ("schema", "schema_version")}
