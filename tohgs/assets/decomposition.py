"""Convex decomposition for simulation, with CoACD and a content-addressed cache.

PyBullet simulates a dynamic mesh as a compound of convex hulls. ``pybullet.vhacd`` segfaults in pybullet
3.2.7 (seen here), so tohgs uses CoACD (collision-aware approximate convex decomposition). A mesh that is
already (nearly) convex is its own decomposition: its convex hull is used without running CoACD.

Results are cached under ``<cache_dir>/coacd/<sha256>.npz``, keyed by the mesh's vertices and faces, the
CoACD settings and CoACD's version, so a rerun after an unrelated setting change costs nothing.

CoACD runs in a child process (:mod:`tohgs.assets.coacd_worker`): on some meshes its C++
code fails an assertion and aborts the process (2 of 64 of pybullet_data's ``random_urdfs`` drawn at
random, e.g. ``378/378.obj``), which no ``try`` in the caller can catch. A crashed child raises
:class:`DecompositionError`, which the objects stage turns into a rejection of that object instead of a
failed run.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import trimesh

from tohgs.assets import coacd_worker
from tohgs.cache import load_or_compute
from tohgs.io import content_key

log = logging.getLogger(__name__)

WORKER = [sys.executable, "-m", coacd_worker.__name__]  # the child's command; + IN.npz OUT.npz


class DecompositionError(RuntimeError):
    """CoACD failed on a mesh: its process crashed or exited with an error (the message says how)."""


@dataclass(frozen=True)
class DecompositionSettings:
    """CoACD settings (see the CoACD paper) plus tohgs's convexity shortcut.

    Attributes:
        threshold: CoACD concavity threshold (smaller = more, tighter parts).
        max_convex_hull: upper bound on the number of parts (-1 = none).
        preprocess_resolution: voxel resolution of CoACD's manifold pre-processing.
        resolution: surface sampling resolution for the concavity metric.
        mcts_iterations, mcts_depth, mcts_nodes: CoACD's tree-search budget.
        convex_tolerance: a mesh whose volume is at least (1 - tolerance) x its hull's volume is treated
            as convex and decomposed into its hull alone.
        seed: CoACD's random seed.
        max_hull_vertices: most vertices per part; a part with more is replaced by the hull of a
            farthest-point subset of its vertices (Bullet's convex contacts cost grows with vertices).
    """

    threshold: float = 0.1
    max_convex_hull: int = 12
    preprocess_resolution: int = 30
    resolution: int = 1000
    mcts_iterations: int = 60
    mcts_depth: int = 2
    mcts_nodes: int = 10
    convex_tolerance: float = 0.01
    seed: int = 0
    max_hull_vertices: int = 64


def cap_hull_vertices(part: trimesh.Trimesh, k: int) -> trimesh.Trimesh:
    """The convex hull of at most ``k`` of ``part``'s vertices, chosen by farthest-point sampling from
    the vertex farthest from the centroid (deterministic; the result lies inside the original hull)."""
    v = np.asarray(part.vertices, dtype=np.float64)
    if len(v) <= k:
        return part
    chosen = [int(np.argmax(((v - v.mean(0)) ** 2).sum(1)))]
    d = ((v - v[chosen[0]]) ** 2).sum(1)
    for _ in range(k - 1):
        chosen.append(int(np.argmax(d)))
        d = np.minimum(d, ((v - v[chosen[-1]]) ** 2).sum(1))
    return trimesh.Trimesh(v[chosen]).convex_hull


def _coacd_version() -> str:
    try:
        from importlib.metadata import version

        return version("coacd")
    except Exception:  # pragma: no cover - metadata missing in odd installs
        return "unknown"


def cache_key(mesh: trimesh.Trimesh, settings: DecompositionSettings) -> str:
    """The content key of the mesh geometry, the settings and the CoACD version (:func:`tohgs.io.content_key`)."""
    return content_key(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64),
                       settings.__dict__, _coacd_version())


def _crash_reason(proc: subprocess.CompletedProcess) -> str:
    """How the child ended, for :class:`DecompositionError`: the signal or exit code and the last line of
    its standard error (CoACD's assertion, a Python traceback's last line)."""
    rc = proc.returncode
    try:
        how = f"was killed by {signal.Signals(-rc).name}" if rc < 0 else f"exited with status {rc}"
    except ValueError:
        how = f"was killed by signal {-rc}"
    lines = [ln.strip() for ln in (proc.stderr or "").splitlines() if ln.strip()]
    last = lines[-1] if lines else "no message"
    if "Assertion" in last:  # a C++ assertion's line starts with the whole function signature
        last = last[last.index("Assertion"):]
    return f"CoACD {how} on this mesh ({last[-300:]})"


def _run_coacd(mesh: trimesh.Trimesh, s: DecompositionSettings) -> list[trimesh.Trimesh]:
    """CoACD's parts of ``mesh`` as convex hulls of positive volume, computed in a child process.

    Raises:
        DecompositionError: the child crashed (CoACD aborted) or failed; the message says how.
    """
    with tempfile.TemporaryDirectory(prefix="tohgs-coacd-") as tmp:
        src, dst = Path(tmp) / "mesh.npz", Path(tmp) / "parts.npz"
        with open(src, "wb") as fh:
            np.savez(fh, vertices=np.asarray(mesh.vertices, dtype=np.float64),
                     faces=np.asarray(mesh.faces, dtype=np.int64), settings=np.str_(json.dumps(asdict(s))))
        # The child imports tohgs from where this process did (a Snakemake script finds it on a sys.path
        # entry the child would not inherit).
        root = str(Path(coacd_worker.__file__).resolve().parents[2])
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
        proc = subprocess.run([*WORKER, str(src), str(dst)], capture_output=True, text=True, check=False, env=env)
        if proc.returncode != 0 or not dst.is_file():
            raise DecompositionError(_crash_reason(proc))
        with np.load(dst, allow_pickle=False) as z:
            raw = [(z[f"v{i}"], z[f"f{i}"]) for i in range(int(z["n"]))]
    out = []
    for verts, faces in raw:
        hull = trimesh.Trimesh(verts, faces).convex_hull
        if hull.volume > 0:
            out.append(hull)
    return out


def _save_parts(parts: list[trimesh.Trimesh], path: Path) -> None:
    arrays = {}
    for i, p in enumerate(parts):
        arrays[f"v{i}"] = np.asarray(p.vertices, dtype=np.float64)
        arrays[f"f{i}"] = np.asarray(p.faces, dtype=np.int64)
    with open(path, "wb") as fh:
        np.savez(fh, n=np.int64(len(parts)), **arrays)


def _load_parts(path: Path) -> list[trimesh.Trimesh]:
    with np.load(path) as z:
        return [trimesh.Trimesh(z[f"v{i}"], z[f"f{i}"], process=False) for i in range(int(z["n"]))]


def convex_decomposition(mesh: trimesh.Trimesh, settings: DecompositionSettings,
                         cache_dir: str | Path | None = None) -> tuple[list[trimesh.Trimesh], str]:
    """Decompose a watertight mesh into convex parts for simulation.

    Args:
        mesh: normalised watertight mesh, metres.
        settings: CoACD settings.
        cache_dir: cache root (``None`` disables the cache).

    Returns:
        ``(parts, method)``: convex hulls (each a ``Trimesh``) and how they were made:
        ``"hull"`` (convex mesh), ``"coacd"`` or ``"coacd-cached"``.

    Raises:
        DecompositionError: CoACD crashed on the mesh (nothing is cached then).
    """
    parts, method = _decompose(mesh, settings, cache_dir)
    return [cap_hull_vertices(p, settings.max_hull_vertices) for p in parts], method


def _decompose(mesh: trimesh.Trimesh, settings: DecompositionSettings,
               cache_dir: str | Path | None) -> tuple[list[trimesh.Trimesh], str]:
    hull = mesh.convex_hull
    if mesh.volume >= (1.0 - settings.convex_tolerance) * hull.volume:
        return [hull], "hull"

    def compute() -> list[trimesh.Trimesh]:
        parts = _run_coacd(mesh, settings)
        if not parts:
            log.warning("CoACD returned no part with positive volume; using the convex hull")
        return parts or [hull]

    parts, hit = load_or_compute(cache_dir, "coacd", cache_key(mesh, settings), ".npz", compute, _save_parts, _load_parts)
    return parts, "coacd-cached" if hit else "coacd"
