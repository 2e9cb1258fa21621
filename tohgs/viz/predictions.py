"""Evaluation figures: predicted hands in their initial and goal scenes (the paper's Figure 6) and predicted
contact maps next to the ground truth (its Figure 5)."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tohgs.assets.supports import read_supports  # noqa: E402
from tohgs.data.maps import read_map_shard  # noqa: E402
from tohgs.data.predictions import read_predictions  # noqa: E402
from tohgs.data.scenes import read_scenes  # noqa: E402
from tohgs.hand.assets import HandAssets  # noqa: E402
from tohgs.sim.scenes import load_configuration  # noqa: E402
from tohgs.sim.world import World  # noqa: E402
from tohgs.viz.render import save_figure, set_equal  # noqa: E402
from tohgs.viz.scenes import COLORS  # noqa: E402

log = logging.getLogger(__name__)

HAND_RGBA = (0.96, 0.78, 0.62, 1.0)


def pick_configs(object_ids: np.ndarray, n: int) -> list[int]:
    """Up to ``n`` row indices of a prediction store, one per object first, then round-robin."""
    by_obj: dict[int, list[int]] = {}
    for i, o in enumerate(np.asarray(object_ids).tolist()):
        by_obj.setdefault(o, []).append(i)
    out: list[int] = []
    k = 0
    while len(out) < n and any(k < len(v) for v in by_obj.values()):
        out += [v[k] for v in by_obj.values() if k < len(v)][: n - len(out)]
        k += 1
    return out


def close_camera(target: np.ndarray, task: str, distance: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    """Eye and look-at points ``distance`` (m) from a target position (the look-at point): from the open
    front of a shelf (-y, slightly above) for Shelving, from the front-right and above otherwise."""
    look = np.asarray(target, dtype=np.float64)
    if task == "shelving":
        d = np.array([0.0, -1.0, 0.25])
    else:
        d = np.array([0.45, -0.75, 0.75])
    return look + distance * d / np.linalg.norm(d), look


def _add_hand(world: World, vertices: np.ndarray, faces: np.ndarray) -> int:
    """A static, visual-only hand mesh in ``world`` (world-frame (V, 3) vertices)."""
    import pybullet as pb

    vis = pb.createVisualShape(pb.GEOM_MESH, vertices=np.asarray(vertices, dtype=np.float64).tolist(),
                               indices=np.asarray(faces, dtype=np.int64).ravel().tolist(), rgbaColor=HAND_RGBA,
                               physicsClientId=world.cid)
    return pb.createMultiBody(0, -1, vis, physicsClientId=world.cid)


def plot_predictions(prediction_stores: list[str | Path], scene_stores: list[str | Path], objects_dir: str | Path,
                     supports_json: str | Path, hand: HandAssets, out_png: str | Path, max_configs: int = 4,
                     labels: list[str] | None = None, size: tuple[int, int] = (320, 240)) -> None:
    """Test configurations (rows) with each method's first kept hand (column pairs, one per store) at the
    initial pose and carried to the goal pose; the same configurations for every method (those of the
    first store). Target red, obstacles blue, base green, hand skin-coloured; a panel says so where the
    method has no prediction for the configuration or discarded all of them."""
    stores = [read_predictions(p) for p in prediction_stores]
    labels = labels or [attrs["method"] for _, attrs in stores]
    scenes = {s.object: s for s in (read_scenes(p) for p in scene_stores)}
    supports = read_supports(supports_json)
    first, first_attrs = stores[0]
    rows = pick_configs(first["object_id"], max_configs)
    if not rows:
        raise ValueError(f"{prediction_stores[0]}: no predicted configuration to draw")
    keys = [(first_attrs["objects"][int(first["object_id"][i])], int(first["config_index"][i])) for i in rows]
    faces = np.asarray(hand.closed_faces)
    ncol = 2 * len(stores)
    fig, axes = plt.subplots(len(rows), ncol, figsize=(1.9 * ncol, 1.6 * len(rows) + 0.4), squeeze=False)
    with World() as world:
        for r, (name, c) in enumerate(keys):
            sc = scenes[name]
            for m, ((arrays, attrs), label) in enumerate(zip(stores, labels)):
                where = [i for i in range(len(arrays["object_id"]))
                         if attrs["objects"][int(arrays["object_id"][i])] == name and int(arrays["config_index"][i]) == c]
                kept = np.flatnonzero(arrays["kept"][where[0]]) if where else np.zeros(0, int)
                for k, which in enumerate(("init", "goal")):
                    ax = axes[r, 2 * m + k]
                    ax.set_axis_off()
                    ax.set_title(f"{label}, {which}" if r == 0 else which, fontsize=7)
                    if not len(kept):
                        ax.text(0.5, 0.5, "no prediction" if not where else "all discarded", ha="center",
                                va="center", fontsize=7, transform=ax.transAxes)
                        continue
                    target = sc.target_init_pose[c, :3] if which == "init" else sc.target_goal_pose[c, :3]
                    verts = hand.vertices(arrays[f"grasp_{which}"][where[0], kept[:1]])[0]
                    # toward the hand by at most 6 cm: a hand at the target is whole in view with the scene
                    # around both; a hand far from it is left out of view rather than the target
                    shift = 0.5 * (verts.mean(0) - target)
                    shift *= min(1.0, 0.06 / max(float(np.linalg.norm(shift)), 1e-9))
                    eye, look = close_camera(target + shift, first_attrs["task"])
                    load_configuration(world, sc, c, objects_dir, supports, which=which, static=True, colors=COLORS)
                    _add_hand(world, verts, faces)
                    ax.imshow(world.render(eye, look, *size))
            axes[r, 0].text(-0.05, 0.5, f"{name} #{c}", rotation=90, ha="right", va="center", fontsize=7,
                            transform=axes[r, 0].transAxes)
    fig.suptitle(f"{first_attrs['task']}: each method's first kept hand (initial | goal), the same configurations"
                 if len(stores) > 1 else f"{first_attrs['task']}, {labels[0]}:\nthe first kept hand", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out_png)
    log.info("wrote %s (%d configurations x %d methods)", out_png, len(rows), len(stores))


def plot_contact_maps(prediction_stores: list[str | Path], test_shards: list[str | Path], out_png: str | Path,
                      per_task: int = 2, samples: int = 2, labels: dict[str, str] | None = None) -> None:
    """Per task, test configurations with ground-truth grasps (rows): a ground-truth contact map, then
    ``samples`` sampled maps of the same configuration from each method (the stores' methods, in their
    order; ``labels`` names them), on the object cloud (1 = touching). The configurations are picked from
    each task's first method and drawn for every method that predicted them."""
    labels = labels or {}
    shards: dict[str, list] = {}
    for p in test_shards:
        sh = read_map_shard(p)
        shards.setdefault(sh.attrs["task"], []).append(sh)
    stores: dict[str, dict[str, tuple]] = {}  # task -> method -> (arrays, row of (object, config))
    for store in prediction_stores:
        arrays, attrs = read_predictions(store)
        key = {(int(o), int(c)): i for i, (o, c) in enumerate(zip(arrays["object_id"], arrays["config_index"]))}
        stores.setdefault(attrs["task"], {})[attrs["method"]] = (arrays, key)
    methods = list(dict.fromkeys(m for by in stores.values() for m in by))
    picks = []
    for task, by_method in stores.items():
        arrays, key = next(iter(by_method.values()))
        found = []
        for sh in shards.get(task, []):
            for c in np.unique(sh.grasp_config):
                k = (int(sh.object_id[c]), int(sh.config_index[c]))
                if k in key:
                    found.append((sh, int(c), int(np.flatnonzero(sh.grasp_config == c)[0]), k))
        order = pick_configs(np.array([f[3][0] for f in found]), per_task)
        picks += [(task, *found[k]) for k in order]
    if not picks:
        raise ValueError("no test configuration has both ground-truth grasps and predictions")
    cols = 1 + samples * len(methods)
    fig = plt.figure(figsize=(2.3 * cols, 2.5 * len(picks)))
    for r, (task, sh, c, g, k) in enumerate(picks):
        pts = sh.points[c]
        name = sh.attrs["objects"][int(sh.object_id[c])]
        maps: list[tuple[str, np.ndarray | None]] = [("ground truth", sh.contact[g])]
        for m in methods:
            arrays, key = stores[task].get(m, (None, {}))
            pred = arrays["contact"][key[k]] if k in key else None
            maps += [(f"{labels.get(m, m)} {j + 1}", None if pred is None or j >= len(pred) else pred[j])
                     for j in range(samples)]
        for j, (label, values) in enumerate(maps):
            ax = fig.add_subplot(len(picks), cols, r * cols + j + 1, projection="3d")
            ax.view_init(25, -60)
            if values is None:
                ax.set_axis_off()
                ax.text2D(0.5, 0.5, "not predicted", ha="center", transform=ax.transAxes, fontsize=7)
            else:
                ax.scatter(*pts.T, s=4, c=values, cmap="inferno", vmin=0, vmax=1)
                set_equal(ax, pts, pad=0.1)
            ax.set_title(f"{task}: {name} #{int(sh.config_index[c])}\n{label}" if j == 0 else label, fontsize=8)
    shown = " | ".join(labels.get(m, m) for m in methods)
    fig.suptitle(f"Contact maps of test configurations: ground truth | {shown} (samples; 1 = touching)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    save_figure(fig, out_png)
    log.info("wrote %s (%d configurations, %d methods)", out_png, len(picks), len(methods))
