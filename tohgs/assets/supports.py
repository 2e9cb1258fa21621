"""Static supports of the task scenes: the table and parametric shelves, built from boxes.

Frames (metres, z up):

- Table: a box of ``size`` (x, y, z) whose top face is the plane z = 0, centred on the origin in x and y.
  The paper's table is 1.5 x 1.0 x 0.05 m.
- Shelf: its footprint is centred on the origin in x and y and stands on z = 0; it is open at the front
  (-y), with a back panel at +y, two side panels at +-x and ``levels`` storage levels, each a board with
  ``clearance`` free height above it. The paper took shelves from ShapeNet, which is not redistributable;
  tohgs generates them, a few sizes from the config.

Every support is a list of :class:`Box` (exact PyBullet primitives) plus a merged watertight mesh for
inside tests and pictures.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh


@dataclass(frozen=True)
class Box:
    """An axis-aligned box: ``center`` (3,) and ``half_extents`` (3,), metres, in the support's frame."""

    center: tuple[float, float, float]
    half_extents: tuple[float, float, float]

    def mesh(self) -> trimesh.Trimesh:
        m = trimesh.creation.box(extents=2 * np.asarray(self.half_extents))
        m.apply_translation(self.center)
        return m


@dataclass(frozen=True)
class Surface:
    """A horizontal rectangle where objects may be placed: top height ``z`` and its x/y ranges (metres)."""

    z: float
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    clearance: float | None = None  # free height above it (None: unbounded)


@dataclass(frozen=True)
class Support:
    """A static support (table or shelf) made of boxes, with the surfaces objects rest on."""

    name: str
    kind: str
    boxes: list[Box]
    surfaces: list[Surface]
    params: dict[str, Any] = field(default_factory=dict)

    def mesh(self) -> trimesh.Trimesh:
        """One watertight mesh (boolean union of the boxes)."""
        meshes = [b.mesh() for b in self.boxes]
        if len(meshes) == 1:
            return meshes[0]
        return trimesh.boolean.union(meshes, engine="manifold")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> "Support":
        return Support(d["name"], d["kind"], [Box(tuple(b["center"]), tuple(b["half_extents"])) for b in d["boxes"]],
                       [Surface(s["z"], tuple(s["x_range"]), tuple(s["y_range"]), s.get("clearance"))
                        for s in d["surfaces"]], dict(d.get("params", {})))


def make_table(size: tuple[float, float, float] = (1.5, 1.0, 0.05)) -> Support:
    """The table: a box with its top face on z = 0."""
    sx, sy, sz = (float(v) for v in size)
    if min(sx, sy, sz) <= 0:
        raise ValueError(f"table size must be positive, got {size}")
    box = Box((0.0, 0.0, -sz / 2), (sx / 2, sy / 2, sz / 2))
    return Support("table", "table", [box], [Surface(0.0, (-sx / 2, sx / 2), (-sy / 2, sy / 2), None)],
                   {"size": [sx, sy, sz]})


def make_shelf(name: str, width: float, depth: float, clearance: float, levels: int,
               thickness: float = 0.02) -> Support:
    """A shelf of ``levels`` boards (bottom board included) with sides, back and a top board.

    Args:
        name: its identifier (``shelf-<name>`` in file names).
        width: outer width along x, metres.
        depth: outer depth along y, metres.
        clearance: free height between a board's top and the next board's bottom, metres.
        levels: number of storage levels (>= 1).
        thickness: panel thickness, metres.
    """
    if levels < 1 or min(width, depth, clearance, thickness) <= 0:
        raise ValueError(f"shelf '{name}': invalid dimensions width={width} depth={depth} "
                         f"clearance={clearance} levels={levels} thickness={thickness}")
    t = thickness
    height = levels * clearance + (levels + 1) * t
    inner_w = width - 2 * t
    boxes = [
        Box((-(width - t) / 2, 0.0, height / 2), (t / 2, depth / 2, height / 2)),  # left side
        Box(((width - t) / 2, 0.0, height / 2), (t / 2, depth / 2, height / 2)),   # right side
        Box((0.0, (depth - t) / 2, height / 2), (inner_w / 2, t / 2, height / 2)),  # back
    ]
    surfaces = []
    board_depth = depth - t
    for k in range(levels + 1):
        z0 = k * (clearance + t)
        boxes.append(Box((0.0, -t / 2, z0 + t / 2), (inner_w / 2, board_depth / 2, t / 2)))
        if k < levels:
            surfaces.append(Surface(z0 + t, (-inner_w / 2, inner_w / 2), (-depth / 2, depth / 2 - t), clearance))
    return Support(f"shelf-{name}", "shelf", boxes, surfaces,
                   {"width": width, "depth": depth, "clearance": clearance, "levels": levels,
                    "thickness": t, "height": height})


def build_supports(table_size: list[float], shelves: list[dict[str, Any]]) -> list[Support]:
    """The table and every configured shelf (``objects.supports`` block)."""
    out = [make_table(tuple(table_size))]
    for s in shelves:
        out.append(make_shelf(s["name"], s["width"], s["depth"], s["clearance"], s["levels"], s["thickness"]))
    return out


def write_supports(table_size: list[float], shelves: list[dict[str, Any]], out_dir: str | Path) -> list[Support]:
    """Write ``<name>.obj`` for every support and ``supports.json`` (boxes and surfaces) into ``out_dir``."""
    from tohgs.io import atomic_dir, write_json

    supports = build_supports(table_size, shelves)
    with atomic_dir(out_dir) as tmp:
        for s in supports:
            s.mesh().export(Path(tmp) / f"{s.name}.obj")
        write_json(Path(tmp) / "supports.json", {"supports": [s.to_dict() for s in supports]})
    return supports


def read_supports(path: str | Path) -> dict[str, Support]:
    """Read ``supports.json``; returns supports by name."""
    import json

    data = json.loads(Path(path).read_text())
    if "supports" not in data:
        raise ValueError(f"{path}: not a tohgs supports file (no 'supports' key)")
    return {d["name"]: Support.from_dict(d) for d in data["supports"]}
