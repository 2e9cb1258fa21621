"""The 23 bricks of the Stacking task, built from fundamental shapes with exact booleans (manifold3d).

The paper made 23 distinct bricks of simple geometry for Stacking; their files are not public, so tohgs
generates its own: prisms of several cross-sections, cylinders, wedges, an arch, L/T/U/Z/cross shapes and
so on, each sized for a human hand (3 to 10 cm) and resting on a flat face (the base face at z = 0 before
normalisation). Every brick is a closed manifold by construction.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh
from manifold3d import CrossSection, Manifold

from tohgs.assets.sources import BRICK_NAMES

_SEGMENTS = 48  # circle resolution for round bricks


def _box(x: float, y: float, z: float) -> Manifold:
    """Axis-aligned box with its base centred at the origin (base face on z = 0)."""
    return Manifold.cube((x, y, z), center=True).translate((0.0, 0.0, z / 2))


def _cylinder(r: float, h: float, segments: int = _SEGMENTS, r_top: float | None = None) -> Manifold:
    return Manifold.cylinder(h, r, r if r_top is None else r_top, segments, False)


def _prism(polygon: list[tuple[float, float]], h: float) -> Manifold:
    """Extrude a counter-clockwise 2-D polygon (x, y in metres) along +z by ``h``, centred in x/y."""
    poly = np.asarray(polygon, dtype=np.float64)
    poly = poly - (poly.min(0) + poly.max(0)) / 2
    return CrossSection([poly.tolist()]).extrude(h)


def _regular_polygon(n: int, r: float, phase: float = 0.0) -> list[tuple[float, float]]:
    a = phase + 2 * np.pi * np.arange(n) / n
    return list(zip(r * np.cos(a), r * np.sin(a)))


def _lying(m: Manifold) -> Manifold:
    """Turn a shape extruded along +z onto its side (extrusion axis along +y), base on z = 0."""
    m = m.rotate((90.0, 0.0, 0.0))
    x0, y0, z0, x1, y1, _ = m.bounding_box()
    return m.translate((-(x0 + x1) / 2, -(y0 + y1) / 2, -z0))


def _arch() -> Manifold:
    body = _box(0.09, 0.04, 0.05)
    hole = Manifold.cylinder(0.06, 0.022, 0.022, _SEGMENTS, True).rotate((90.0, 0.0, 0.0))
    return body - hole


def _tube() -> Manifold:
    return _cylinder(0.032, 0.05) - Manifold.cylinder(0.07, 0.018, 0.018, _SEGMENTS, True)


def _stairs() -> Manifold:
    return _box(0.09, 0.04, 0.02) + _box(0.06, 0.04, 0.02).translate((0.015, 0, 0.02)) \
        + _box(0.03, 0.04, 0.02).translate((0.03, 0, 0.04))


def _house() -> Manifold:
    return _box(0.05, 0.05, 0.04) + _lying(_prism([(0, 0), (0.05, 0), (0.025, 0.025)], 0.05)).translate((0, 0, 0.039))


#: Name -> builder. Dimensions in metres. Order is stable: it defines brick ids.
BRICKS: dict[str, Callable[[], Manifold]] = {
    "cube": lambda: _box(0.05, 0.05, 0.05),
    "cuboid": lambda: _box(0.08, 0.04, 0.04),
    "slab": lambda: _box(0.08, 0.06, 0.025),
    "bar": lambda: _box(0.10, 0.03, 0.03),
    "cylinder": lambda: _cylinder(0.025, 0.06),
    "disc": lambda: _cylinder(0.035, 0.03),
    "triangular-prism": lambda: _lying(_prism(_regular_polygon(3, 0.035, np.pi / 2), 0.06)),
    "pentagonal-prism": lambda: _prism(_regular_polygon(5, 0.032, np.pi / 2), 0.05),
    "hexagonal-prism": lambda: _prism(_regular_polygon(6, 0.03), 0.05),
    "octagonal-prism": lambda: _prism(_regular_polygon(8, 0.03, np.pi / 8), 0.04),
    "wedge": lambda: _lying(_prism([(0, 0), (0.08, 0), (0, 0.045)], 0.05)),
    "trapezoid-prism": lambda: _lying(_prism([(0, 0), (0.08, 0), (0.06, 0.04), (0.02, 0.04)], 0.05)),
    "half-cylinder": lambda: _lying(_prism(
        [(0.035 * np.cos(a), 0.035 * np.sin(a)) for a in np.linspace(0, np.pi, _SEGMENTS // 2 + 1)], 0.06)),
    "arch": _arch,
    "tube": _tube,
    "frustum": lambda: _cylinder(0.045, 0.045, 4, r_top=0.025).rotate((0.0, 0.0, 45.0)),
    "l-shape": lambda: _prism([(0, 0), (0.08, 0), (0.08, 0.03), (0.03, 0.03), (0.03, 0.07), (0, 0.07)], 0.035),
    "t-shape": lambda: _prism([(0, 0), (0.09, 0), (0.09, 0.03), (0.06, 0.03), (0.06, 0.08), (0.03, 0.08),
                               (0.03, 0.03), (0, 0.03)], 0.035),
    "u-shape": lambda: _prism([(0, 0), (0.08, 0), (0.08, 0.06), (0.055, 0.06), (0.055, 0.025), (0.025, 0.025),
                               (0.025, 0.06), (0, 0.06)], 0.04),
    "z-shape": lambda: _prism([(0, 0), (0.06, 0), (0.06, 0.03), (0.09, 0.03), (0.09, 0.06), (0.03, 0.06),
                               (0.03, 0.03), (0, 0.03)], 0.035),
    "cross": lambda: _prism([(0.03, 0), (0.06, 0), (0.06, 0.03), (0.09, 0.03), (0.09, 0.06), (0.06, 0.06),
                             (0.06, 0.09), (0.03, 0.09), (0.03, 0.06), (0, 0.06), (0, 0.03), (0.03, 0.03)], 0.03),
    "stairs": _stairs,
    "house": _house,
}


if tuple(BRICKS) != BRICK_NAMES:  # the selection lists them without building them (tohgs.assets.sources)
    raise RuntimeError("tohgs.assets.bricks.BRICKS and tohgs.assets.sources.BRICK_NAMES list different bricks")


def brick_names() -> list[str]:
    """The brick names in their stable order."""
    return list(BRICKS)


def make_brick(name: str, scale: float = 1.0) -> trimesh.Trimesh:
    """Build brick ``name`` as a watertight ``Trimesh`` in metres (base face on z = 0).

    Raises:
        KeyError: unknown name (the message lists the known ones).
    """
    if name not in BRICKS:
        raise KeyError(f"unknown brick '{name}'; known bricks: {', '.join(BRICKS)}")
    solid = BRICKS[name]().scale((scale, scale, scale))
    mesh = solid.to_mesh()
    verts = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(mesh.tri_verts, dtype=np.int64)
    out = trimesh.Trimesh(verts, faces, process=True)
    return out
