"""The objects figure: a grid of the selected objects and all bricks, labelled with split and size."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from tohgs.assets.mesh import object_mesh
from tohgs.assets.objects import read_catalog
from tohgs.viz.render import draw_mesh, save_figure, set_equal

log = logging.getLogger(__name__)

SPLIT_COLORS = {"train": "tab:blue", "val": "tab:green", "test": "tab:orange"}


def plot_objects(catalog_csv: str | Path, out_png: str | Path, max_objects: int = 24, seed: int = 0,
                 ncols: int = 8) -> None:
    """Render every accepted brick and up to ``max_objects`` accepted other objects (seeded choice).

    Colour = split (train blue, val green, test orange); the title gives the name and the extents in cm.
    All panels share one scale, so sizes compare across panels.
    Rejected objects are listed with their reasons under the grid.
    """
    catalog_csv = Path(catalog_csv)
    full = read_catalog(catalog_csv, status=None)
    ok = full[full.status == "ok"]
    objs = ok[ok.source != "bricks"]
    if len(objs) > max_objects:
        objs = objs.iloc[np.sort(np.random.default_rng(seed).choice(len(objs), max_objects, replace=False))]
    shown = list(objs.itertuples()) + list(ok[ok.source == "bricks"].itertuples())
    if not shown:
        raise ValueError(f"{catalog_csv}: no accepted object to draw")
    rejected = full[full.status != "ok"]
    radius = 0.55 * max(max(r.extent_x, r.extent_y, r.extent_z) for r in shown)
    nrows = int(np.ceil(len(shown) / ncols))
    fig = plt.figure(figsize=(2.2 * ncols, 2.3 * nrows + 0.3 + 0.18 * len(rejected)))
    for k, row in enumerate(shown):
        mesh = object_mesh(catalog_csv.parent, row.name)
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        ax.view_init(elev=25, azim=-60)
        draw_mesh(ax, mesh.vertices, mesh.faces, SPLIT_COLORS.get(row.split, "tab:gray"))
        set_equal(ax, mesh.vertices, radius=radius)
        ext = 100 * np.array([row.extent_x, row.extent_y, row.extent_z])
        ax.set_title(f"{row.name}\n{row.split} {ext[0]:.0f}x{ext[1]:.0f}x{ext[2]:.0f} cm", fontsize=7)
    lines = [f"{r.status} {r.name or r.source_path}: {r.reason}" for r in rejected.itertuples()]
    legend = f"colour = split: train blue, val green, test orange; every panel spans {200 * radius:.0f} cm"
    fig.text(0.01, 0.005, "\n".join([legend] + lines), fontsize=7, va="bottom", family="monospace")
    fig.tight_layout(rect=(0, 0.03 + 0.012 * len(lines), 1, 1))
    save_figure(fig, out_png)
    log.info("wrote %s: %d objects, %d rejected listed", out_png, len(shown), len(rejected))
