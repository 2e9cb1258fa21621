"""Content-addressed caches under ``cache_dir`` (the config's ``cache_dir``): load or compute, one pattern.

An entry is ``<cache_dir>/<kind>/<key><suffix>``, the key a :func:`tohgs.io.content_key` of everything the
value depends on. An entry is written atomically; one that cannot be read is logged, recomputed and
replaced, never trusted. Deleting the folder never changes a result, only the time to the next one.
Used by the convex decompositions (``coacd``), the SDF grids (``sdf``) and the surface voxels (``voxels``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from tohgs.io import atomic_path

log = logging.getLogger(__name__)
T = TypeVar("T")


def load_or_compute(cache_dir: str | Path | None, kind: str, key: str, suffix: str, compute: Callable[[], T],
                    save: Callable[[T, Path], None], load: Callable[[Path], T]) -> tuple[T, bool]:
    """The cached value of ``key``, or ``compute()`` stored for next time; ``(value, from_cache)``.

    Args:
        cache_dir: the cache root; None computes without caching.
        kind: the entry's folder (``"sdf"``, ...).
        key: the content key.
        suffix: the file suffix (``".npz"``).
        compute: makes the value.
        save: ``save(value, path)`` writes it to a (temporary) path.
        load: ``load(path)`` reads it back; any exception means an unreadable entry.
    """
    path = Path(cache_dir) / kind / f"{key}{suffix}" if cache_dir is not None else None
    if path is not None and path.is_file():
        try:
            return load(path), True
        except Exception as exc:  # a damaged entry is recomputed, not trusted
            log.warning("ignoring unreadable cache entry %s (%s)", path, exc)
    value = compute()
    if path is not None:
        with atomic_path(path) as tmp:
            save(value, tmp)
    return value, False
