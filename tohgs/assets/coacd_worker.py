"""The child process that runs CoACD for :mod:`tohgs.assets.decomposition`.

``python -m tohgs.assets.coacd_worker IN.npz OUT.npz``: reads a mesh (``vertices`` (V, 3) float64 metres,
``faces`` (F, 3) int64) and the settings (``settings``, :class:`~tohgs.assets.decomposition.DecompositionSettings`
as JSON) from IN, writes CoACD's parts to OUT (``n``, then ``v<i>`` (V_i, 3) and ``f<i>`` (F_i, 3)). A process
of its own because CoACD aborts the process on some meshes; it imports only numpy and CoACD so that
starting it costs about 0.2 s.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def coacd_parts(vertices: np.ndarray, faces: np.ndarray, s: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """CoACD's parts ``[(vertices (V, 3), faces (F, 3)), ...]`` of one mesh, in this process (``s``: the
    settings as a dict)."""
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)),
        threshold=s["threshold"], max_convex_hull=s["max_convex_hull"], preprocess_mode="auto",
        preprocess_resolution=s["preprocess_resolution"], resolution=s["resolution"],
        mcts_iterations=s["mcts_iterations"], mcts_max_depth=s["mcts_depth"], mcts_nodes=s["mcts_nodes"],
        seed=s["seed"],
    )
    return [(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)) for v, f in parts]


def main(argv: list[str]) -> int:
    """Read the mesh and settings from ``argv[0]``, write the parts to ``argv[1]``."""
    if len(argv) != 2:
        print("usage: python -m tohgs.assets.coacd_worker IN.npz OUT.npz", file=sys.stderr)
        return 2
    src, dst = argv
    with np.load(src, allow_pickle=False) as z:
        vertices, faces, settings = z["vertices"], z["faces"], json.loads(str(z["settings"]))
    parts = coacd_parts(vertices, faces, settings)
    arrays = {f"v{i}": v for i, (v, _) in enumerate(parts)} | {f"f{i}": f for i, (_, f) in enumerate(parts)}
    with open(dst, "wb") as fh:
        np.savez(fh, n=np.int64(len(parts)), **arrays)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
