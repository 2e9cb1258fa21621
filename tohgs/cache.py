"""Content-addressed caches under ``cache_dir`` (the config's ``cache_dir``): load or compute, one pattern.

An entry is ``<cache_dir>/<kind>/<key><suffix>``, the key a :func:`tohgs.io.content_key` of everything the
value depends on, with the SHA-256 of its bytes beside it (``<key><suffix>.sha256``, written before the entry
is renamed into place). An entry is read only if its bytes match that checksum (hashed once per process per
version of the file): one that does not (bit flips, a truncated copy, an entry of an older tohgs without a
checksum) or cannot be read is logged, recomputed and replaced, never trusted. Deleting the folder never
changes a result, only the time to the next one. Used by the convex decompositions (``coacd``), the SDF grids
(``sdf``), the surface voxels (``voxels``) and SD's collision hand (``sd_hand``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from tohgs.io import atomic_path, file_sha256

log = logging.getLogger(__name__)
T = TypeVar("T")

#: The suffix of an entry's checksum file, after the entry's own name.
CHECKSUM_SUFFIX = ".sha256"


def _checksum_path(path: Path) -> Path:
    return path.with_name(path.name + CHECKSUM_SUFFIX)


def verified(path: Path) -> str | None:
    """Why cache entry ``path`` may not be trusted, or None when its bytes match its recorded SHA-256."""
    record = _checksum_path(path)
    try:
        want = record.read_text().strip()
    except FileNotFoundError:
        return f"no checksum beside it ({record.name})"
    except (OSError, UnicodeDecodeError) as exc:
        return f"its checksum {record.name} is unreadable ({exc})"
    if file_sha256(path) != want:
        return f"its bytes do not match the SHA-256 in {record.name} (damaged after it was written)"
    return None


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
        problem = verified(path)
        if problem is None:
            try:
                return load(path), True
            except Exception as exc:  # a damaged entry is recomputed, not trusted
                problem = f"unreadable ({exc})"
        log.warning("ignoring cache entry %s: %s; recomputing it", path, problem)
    value = compute()
    if path is not None:
        with atomic_path(path) as tmp:
            save(value, tmp)
            with atomic_path(_checksum_path(path)) as tmp_sum:
                tmp_sum.write_text(file_sha256(tmp) + "\n")
    return value, False
