"""Map figure: object clouds coloured by D_init, D_goal and the contact map, next to the hand and scene."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tohgs.data.maps import read_map_shard  # noqa: E402
from tohgs.hand.assets import HandAssets  # noqa: E402
from tohgs.viz.render import draw_mesh, save_figure, set_equal  # noqa: E402

log = logging.getLogger(__name__)


def plot_maps(shard_paths: list[str | Path], hand: HandAssets, out_png: str | Path, per_task: int = 2) -> None:
    """``per_task`` training samples of every task (rows): D_init, D_goal and contact on the object cloud,
    and the hand with the object and the nearby scene cloud."""
    chosen = []
    by_task: dict[str, list] = {}
    for p in shard_paths:
        sh = read_map_shard(p)
        if sh.attrs["split"] == "train" and sh.n_grasps:
            by_task.setdefault(sh.attrs["task"], []).append(sh)
    for task, shards in sorted(by_task.items()):
        sh = shards[0]
        # Grasps of different configurations (objects) where there are several.
        first = [int(np.flatnonzero(sh.grasp_config == c)[0]) for c in np.unique(sh.grasp_config)]
        rows = [first[i] for i in np.linspace(0, len(first) - 1, min(per_task, len(first))).round().astype(int)]
        chosen += [(task, sh, r) for r in dict.fromkeys(rows)]
    cols = ["D_init", "D_goal", "contact", "hand"]
    fig = plt.figure(figsize=(3.0 * len(cols), 3.0 * max(1, len(chosen))))
    faces = np.asarray(hand.closed_faces)
    for i, (task, sh, g) in enumerate(chosen):
        c = int(sh.grasp_config[g])
        pts = sh.points[c]
        name = sh.attrs["objects"][int(sh.object_id[c])]
        hv = hand.vertices(sh.grasp[g : g + 1])[0]
        values = {"D_init": sh.d_init[c], "D_goal": sh.d_goal[c], "contact": sh.contact[g]}
        for j, col in enumerate(cols):
            ax = fig.add_subplot(len(chosen), len(cols), i * len(cols) + j + 1, projection="3d")
            ax.view_init(25, -60)
            if col == "hand":
                near = sh.scene[c][np.linalg.norm(sh.scene[c], axis=1) < 0.15]
                ax.scatter(*near.T, s=1, c="0.6")
                ax.scatter(*pts.T, s=2, c="tab:orange")
                draw_mesh(ax, hv, faces, color="peachpuff", max_faces=3000, alpha=0.8)
                set_equal(ax, np.concatenate([pts, hv]), pad=0.05)
                ax.set_title(f"{task}: {name} (config {int(sh.config_index[c])})", fontsize=8)
            else:
                sc = ax.scatter(*pts.T, s=4, c=values[col], cmap="inferno", vmin=0, vmax=1)
                set_equal(ax, pts, pad=0.1)
                ax.set_title(f"{col} (max {values[col].max():.2f})", fontsize=8)
                if j == 2:
                    fig.colorbar(sc, ax=ax, shrink=0.6)
    fig.suptitle("Maps of training samples: 1 = touching (scene for D_init / D_goal, hand for contact)", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    save_figure(fig, out_png)
    log.info("drew %d samples", len(chosen))
