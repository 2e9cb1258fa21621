"""The hand figure: rest pose, presets, part labels and contact candidates, from two viewpoints."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch

from tohgs.hand.model import HandModel
from tohgs.viz.render import draw_mesh, save_figure, set_equal

log = logging.getLogger(__name__)

#: Two viewpoints in the canonical frame: looking at the palm (from -y) and from the thumb side (+z).
VIEWS = (("palm side (from -y)", 0.0, -90.0), ("thumb side (from +z)", 90.0, -90.0))


def plot_hand(hand: HandModel, out_png: str | Path) -> None:
    """Render the flat hand and each preset, the 16 part labels and the contact candidates and tips."""
    presets = ["flat"] + [p for p in ("relaxed", "power", "pinch") if p in hand.assets.presets]
    poses = torch.stack([hand.preset(p)[0] for p in presets])
    with torch.no_grad():
        out = hand(poses)
    verts = out.vertices.cpu().numpy()
    joints = out.joints.cpu().numpy()
    faces = hand.assets.closed_faces
    cmap = plt.get_cmap("tab20")
    labels = hand.assets.part_labels
    face_lab = labels[faces[:, 0]]
    panels = [(f"{p}", verts[i], None, joints[i]) for i, p in enumerate(presets)]
    panels.append(("16 part labels", verts[0], np.asarray([cmap(l % 20)[:3] for l in face_lab]), None))
    panels.append(("contact candidates (red), tips (black)", verts[0], None, None))
    fig = plt.figure(figsize=(3.0 * len(panels), 5.4))
    lim = np.concatenate([verts.reshape(-1, 3)]).astype(np.float64)
    radius = 0.42 * (lim.max(0) - lim.min(0)).max()
    for col, (title, v, fc, j) in enumerate(panels):
        for row, (vname, elev, azim) in enumerate(VIEWS):
            ax = fig.add_subplot(2, len(panels), row * len(panels) + col + 1, projection="3d")
            ax.view_init(elev=elev, azim=azim, roll=0)
            draw_mesh(ax, v, faces, "burlywood", face_colors=fc, alpha=0.35 if col == len(panels) - 1 else 1.0)
            if col == len(panels) - 1:
                c = v[hand.assets.contact_ids]
                ax.scatter(c[:, 0], c[:, 1], c[:, 2], s=10, c="red", depthshade=False, zorder=10)
                t = v[hand.assets.tip_ids]
                ax.scatter(t[:, 0], t[:, 1], t[:, 2], s=14, c="black", depthshade=False)
            if j is not None:
                ax.scatter(j[:, 0], j[:, 1], j[:, 2], s=4, c="navy", depthshade=False)
            set_equal(ax, v, radius=radius)
            ax.set_title(f"{title}\n{vname}" if row == 0 else vname, fontsize=8)
    fig.suptitle(f"hand '{hand.name}' in MANO's canonical frame (fingers -x, palm -y, thumb +z); "
                 f"{hand.n_vertices} vertices, {len(hand.assets.contact_ids)} contact candidates", fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.9, wspace=0, hspace=0.08)
    save_figure(fig, out_png)
    log.info("wrote %s", out_png)
