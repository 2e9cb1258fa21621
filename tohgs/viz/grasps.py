"""Prior-grasp figure: accepted grasps from two viewpoints and rejected ones labelled with why."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tohgs.assets.mesh import object_mesh  # noqa: E402
from tohgs.data.grasps import read_prior_grasps  # noqa: E402
from tohgs.grasps.filter import CHECKS  # noqa: E402
from tohgs.hand.assets import HandAssets  # noqa: E402
from tohgs.viz.render import draw_mesh, save_figure, set_equal  # noqa: E402

log = logging.getLogger(__name__)

VIEWS = ((25.0, -60.0), (-10.0, 120.0))  # (elevation, azimuth), degrees: front-above and back-below


def pick_objects(names: list[str], n: int) -> list[str]:
    """Up to ``n`` names, half bricks and half other objects, evenly spread over the sorted lists."""
    bricks = sorted(x for x in names if x.startswith("brick-"))
    others = sorted(x for x in names if not x.startswith("brick-"))
    n_b = min(len(bricks), n // 2) if others else min(len(bricks), n)
    n_o = min(len(others), n - n_b)
    n_b = min(len(bricks), n - n_o)

    def spread(xs: list[str], k: int) -> list[str]:
        return [xs[i] for i in np.linspace(0, len(xs) - 1, k).round().astype(int)] if k else []

    return spread(others, n_o) + spread(bricks, n_b)


def _why(flags: dict[str, np.ndarray], i: int, g) -> str:
    reasons = []
    for c in CHECKS:
        if c == "sd" and not np.isfinite(g.sd[i]):
            continue  # not simulated: it failed the screen (energy or joints), listed below
        if not flags[c][i]:
            detail = {"pv": f"PV {g.pv[i] * 1e6:.1f} cm3", "sd": f"SD {g.sd[i] * 100:.1f} cm",
                      "contact": f"gap {g.contact_distance[i] * 1000:.0f} mm", "joints": "joint limits",
                      "energy": f"E fc {g.energies['fc'][i]:.2f} dis {g.energies['dis'][i] * 1000:.0f} mm"}[c]
            reasons.append(detail)
    return "rejected: " + ", ".join(reasons)


def plot_prior_grasps(store_paths: list[str | Path], objects_dir: str | Path, hand: HandAssets, out_png: str | Path,
                      n_objects: int = 6, n_accepted: int = 2) -> None:
    """Per object (rows): ``n_accepted`` accepted grasps from two viewpoints, then one rejected grasp.

    Accepted grasps are the lowest-energy ones; the rejected one is the lowest-energy failure, labelled
    with the checks it fails.
    """
    stores = {Path(p).name.removesuffix(".zarr"): p for p in store_paths}
    names = pick_objects(list(stores), n_objects)
    cols = 2 * n_accepted + 1
    fig = plt.figure(figsize=(2.6 * cols, 2.7 * max(1, len(names))))
    faces = np.asarray(hand.closed_faces)
    for row, name in enumerate(names):
        g = read_prior_grasps(stores[name], filtered=True)
        mesh = object_mesh(objects_dir, name)
        order = np.argsort(g.energies["total"])
        acc = [i for i in order if g.passed[i]][:n_accepted]
        rej = [i for i in order if not g.passed[i]][:1]
        shown = [(i, v, "accepted") for i in acc for v in range(2)] + [(i, 0, "rejected") for i in rej]
        idx = sorted({i for i, _, _ in shown})
        verts = dict(zip(idx, hand.vertices(g.pose[idx]))) if idx else {}
        for col in range(cols):
            ax = fig.add_subplot(len(names), cols, row * cols + col + 1, projection="3d")
            ax.set_axis_off()
            if col >= len(shown):
                if col == 0:
                    ax.set_title(f"{name}: no grasp", fontsize=8)
                continue
            i, view, kind = shown[col]
            hv = verts[i]
            draw_mesh(ax, mesh.vertices, mesh.faces, color="tab:orange", max_faces=3000)
            draw_mesh(ax, hv, faces, color="peachpuff" if kind == "accepted" else "lightsteelblue", max_faces=4000,
                      alpha=0.9)
            ax.view_init(*VIEWS[view])
            set_equal(ax, np.concatenate([hv, mesh.vertices]), pad=0.02)
            if kind == "accepted":
                title = f"{name} #{i} ({'front' if view == 0 else 'back'})\nSD {g.sd[i] * 100:.1f} cm, PV {g.pv[i] * 1e6:.2f} cm3"
            else:
                title = f"{name} #{i}\n{_why(g.flags, i, g)}"
            ax.set_title(title, fontsize=7, color="black" if kind == "accepted" else "firebrick")
        n_pass = int(g.passed.sum())
        log.info("%s: %d of %d accepted", name, n_pass, len(g))
    fig.suptitle("Prior grasps: accepted (skin, two views each) and a rejected one (blue, with the failed checks)",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    save_figure(fig, out_png)
