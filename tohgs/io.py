"""Small I/O helpers shared by every stage: atomic writes, content keys for caches, logging set-up.

A job writes into a temporary sibling path and renames it into place at the end, so a killed job never
leaves an output that looks complete; the next writer of that path removes what a killed one left behind.
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import json
import logging
import os
import shutil
import socket
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

_UMASK = os.umask(0)
os.umask(_UMASK)


_DIGESTS: dict[tuple[str, int, int, int, int], str] = {}


def stat_key(path: str | Path) -> tuple[str, int, int, int, int]:
    """What identifies one version of a file: its real path, device, inode, size and modification time."""
    st = os.stat(path)
    return (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def file_sha256(path: str | Path) -> str:
    """The SHA-256 (hex) of a file's bytes, read in 1 MiB blocks, computed once per process per version of the
    file (:func:`stat_key`: a file changed in place is hashed again)."""
    key = stat_key(path)
    if key not in _DIGESTS:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        _DIGESTS[key] = h.hexdigest()
    return _DIGESTS[key]


def _tmp_prefix(path: Path) -> str:
    """The name prefix of ``path``'s temporary siblings: ``.<name>.<host>-<pid>.``, so that a later writer
    can tell the leftovers of a killed process (same host, process gone) from a live one's."""
    return f".{path.name}.{_host()}-{os.getpid()}."


def _host() -> str:
    return socket.gethostname().replace(".", "_")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def _stale(tmp: Path, path: Path, host: str) -> bool:
    """Whether ``tmp`` (a sibling named by :func:`_tmp_prefix`) was left by a killed process on this host."""
    rest = tmp.name[len(path.name) + 2:]  # "<host>-<pid>.<random>.tmp"
    owner = rest.split(".", 1)[0]
    h, _, pid = owner.rpartition("-")
    return h == host and pid.isdigit() and not _alive(int(pid))


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Remove the temporary siblings of ``path`` that a killed writer on this host left behind (its process
    no longer exists); a live writer's, or another host's, are kept. A folder a killed :func:`atomic_dir`
    had set aside (``*.old``) is put back in place if ``path`` is missing (killed between its two renames),
    removed otherwise. Returns the removed or restored paths."""
    path = Path(path)
    host = _host()
    removed = []
    if not path.parent.is_dir():
        return removed
    asides = [p for p in path.parent.glob(f".{glob.escape(path.name)}.*.old") if _stale(p, path, host)]
    for old in sorted(asides, key=lambda p: p.stat().st_mtime_ns, reverse=True):
        if not path.exists():
            os.rename(old, path)
            logging.getLogger(__name__).warning("%s: restored from %s, which a killed writer had set aside", path, old)
        else:
            shutil.rmtree(old, ignore_errors=True)
        removed.append(old)
    for tmp in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
        if not _stale(tmp, path, host):
            continue
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        removed.append(tmp)
    return removed


@contextlib.contextmanager
def atomic_dir(path: str | Path) -> Iterator[Path]:
    """Yield a fresh temporary folder next to ``path``; on success it replaces ``path``, on error it is removed.
    Leftover temporary folders of killed writers of ``path`` are removed first.

    The swap keeps a complete copy at every instant: the old folder is renamed aside (``.<name>.<host>-<pid>.
    <random>.old``), the new one renamed into place, then the old one removed. A process killed between the two
    renames leaves the old folder aside, and the next writer of ``path`` puts it back
    (:func:`remove_stale_temporaries`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    tmp = Path(tempfile.mkdtemp(prefix=_tmp_prefix(path), suffix=".tmp", dir=path.parent))
    os.chmod(tmp, 0o777 & ~_UMASK)
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    try:
        if path.exists():
            old = path.parent / f"{_tmp_prefix(path)}{os.urandom(4).hex()}.old"
            os.rename(path, old)
        os.replace(tmp, path)
    except BaseException:
        if old is not None and not path.exists():
            os.rename(old, path)
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old is not None:  # a removal cut short leaves a partial folder aside: renamed so that it is never restored
        dead = old.with_suffix(".tmp")
        os.rename(old, dead)
        shutil.rmtree(dead, ignore_errors=True)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary file path next to ``path``; on success it is renamed to ``path``. Leftover
    temporary files of killed writers of ``path`` are removed first."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix(path), suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def copy_atomic(src: str | Path, dst: str | Path) -> None:
    """Copy the file or folder ``src`` to ``dst`` atomically (:func:`atomic_path`, :func:`atomic_dir`): a reader
    sees the old ``dst`` or the whole copy, never a part. Raises FileNotFoundError naming a missing ``src``."""
    src = Path(src)
    if src.is_dir():
        with atomic_dir(dst) as tmp:
            shutil.copytree(src, tmp, dirs_exist_ok=True)
    elif src.is_file():
        with atomic_path(dst) as tmp:
            shutil.copyfile(src, tmp)
    else:
        raise FileNotFoundError(f"{src}: no such file or folder to copy")


def content_key(*parts: Any) -> str:
    """A cache key by content: the sha256 of arrays (dtype, shape and bytes) and JSON-able values, in order."""
    import numpy as np

    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(json.dumps(part, sort_keys=True).encode())
    return h.hexdigest()


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_json(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically."""
    write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")


def setup_logging(log_path: str | Path | None = None, level: int = logging.INFO) -> None:
    """Send ``logging`` records and stderr (tqdm's progress bars, warnings) to ``log_path``.

    Used by the workflow scripts as their first line; without a path, logs go to stderr.
    """
    if log_path is not None:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        stream = open(log_path, "a", buffering=1)  # noqa: SIM115 - lives as long as the job
        sys.stderr = stream
    logging.basicConfig(level=level, stream=sys.stderr, force=True,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.captureWarnings(True)
