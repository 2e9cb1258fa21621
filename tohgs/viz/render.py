"""Headless mesh rendering with matplotlib (Agg): flat-shaded triangles in a 3-D axis.

Enough for figures of a few thousand triangles per mesh; larger meshes are decimated by face sampling.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

from pathlib import Path  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def shade(normals: np.ndarray, color: str | tuple[float, float, float], ambient: float = 0.35) -> np.ndarray:
    """Lambert shading: (F, 3) unit normals -> (F, 4) RGBA face colours."""
    base = np.asarray(to_rgb(color))
    lam = np.clip(normals @ LIGHT, 0.0, 1.0)
    rgb = base[None] * (ambient + (1 - ambient) * lam[:, None])
    return np.concatenate([np.clip(rgb, 0, 1), np.ones((len(rgb), 1))], axis=1)


def draw_mesh(ax, vertices: np.ndarray, faces: np.ndarray, color: str = "tab:blue", max_faces: int = 6000,
              alpha: float = 1.0, rng: np.random.Generator | None = None,
              face_colors: np.ndarray | None = None) -> None:
    """Draw a triangle mesh ((V, 3) metres, (F, 3) int) into a 3-D matplotlib axis.

    ``face_colors`` (F, 3) RGB in [0, 1], if given, replaces the uniform ``color`` (still shaded).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if len(faces) > max_faces:
        rng = np.random.default_rng(0) if rng is None else rng
        keep = np.sort(rng.choice(len(faces), max_faces, replace=False))
        faces = faces[keep]
        face_colors = None if face_colors is None else np.asarray(face_colors)[keep]
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    colors = shade(n, color)
    if face_colors is not None:
        lam = np.clip(n @ LIGHT, 0.0, 1.0)[:, None]
        colors[:, :3] = np.clip(np.asarray(face_colors)[:, :3] * (0.35 + 0.65 * lam), 0, 1)
    colors[:, 3] = alpha
    coll = Poly3DCollection(tri, facecolors=colors, edgecolors="none", linewidths=0)
    ax.add_collection3d(coll)


def set_equal(ax, points: np.ndarray, pad: float = 0.05, radius: float | None = None) -> None:
    """Equal-aspect limits around (N, 3) points (half-width ``radius`` if given, m), no axes decoration."""
    lo, hi = points.min(0), points.max(0)
    c = (lo + hi) / 2
    r = (hi - lo).max() / 2 * (1 + pad) if radius is None else radius
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))
    ax.set_axis_off()


def save_figure(fig, out_png: str | Path, dpi: int = 90) -> None:
    """Write ``fig`` as a PNG atomically and close it."""
    from tohgs.io import atomic_path

    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
