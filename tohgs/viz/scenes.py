"""Scene figures: initial and goal scenes side by side, rendered with PyBullet's CPU renderer."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tohgs.assets.supports import read_supports  # noqa: E402
from tohgs.data.scenes import read_scenes  # noqa: E402
from tohgs.sim.scenes import load_configuration  # noqa: E402
from tohgs.sim.world import World  # noqa: E402
from tohgs.viz.render import save_figure  # noqa: E402

log = logging.getLogger(__name__)

COLORS = {"target": (0.85, 0.2, 0.15, 1.0), "obstacle": (0.25, 0.45, 0.8, 1.0), "base": (0.3, 0.65, 0.3, 1.0)}


def _camera(scenes, c: int, task: str) -> tuple[np.ndarray, np.ndarray]:
    """Eye and look-at points that frame the target at both poses, the obstacles and the base."""
    pts = [scenes.target_init_pose[c, :3], scenes.target_goal_pose[c, :3]] + [p[:3] for _, p in scenes.obstacles(c)]
    if scenes.base(c) is not None:
        pts.append(scenes.base(c)[1][:3])
    pts = np.asarray(pts)
    look = (pts.min(0) + pts.max(0)) / 2
    span = max(float(np.linalg.norm(pts.max(0) - pts.min(0))), 0.15)
    if task == "shelving":  # from the open front of the shelf (-y), slightly above the board
        return look + np.array([0.0, -1.6 * span - 0.35, 0.18]), look
    return look + np.array([0.3 * span, -0.9 * span - 0.12, 0.6 * span + 0.15]), look


def plot_scenes(scene_paths: list[str | Path], objects_dir: str | Path, supports_json: str | Path, out_png: str | Path,
                task: str, max_configs: int = 6, size: tuple[int, int] = (360, 270)) -> None:
    """Render up to ``max_configs`` configurations (one per object first), initial and goal side by side.

    The target is red, obstacles blue, the base brick green.
    """
    supports = read_supports(supports_json)
    picks = []
    sets = [read_scenes(p) for p in sorted(scene_paths)]
    for k in range(max(len(s) for s in sets) if sets else 0):
        for s in sets:
            if k < len(s) and len(picks) < max_configs:
                picks.append((s, k))
    if not picks:
        raise ValueError(f"no {task} configuration to draw")
    fig, axes = plt.subplots(len(picks), 2, figsize=(7.2, 2.75 * len(picks)), squeeze=False)
    with World() as world:
        for row, (s, c) in enumerate(picks):
            eye, look = _camera(s, c, task)
            for col, which in enumerate(("init", "goal")):
                load_configuration(world, s, c, objects_dir, supports, which=which, static=True, colors=COLORS)
                axes[row, col].imshow(world.render(eye, look, *size))
                axes[row, col].set_axis_off()
                n_obs = s.obstacle_offsets[c + 1] - s.obstacle_offsets[c]
                base = s.base(c)
                extra = f", base {base[0]}" if base else f", {n_obs} obstacles"
                axes[row, col].set_title(f"{s.object} #{c} {which}{extra}", fontsize=8)
    fig.suptitle(f"{task}: target red, obstacles blue, base green (initial | goal)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out_png)
    log.info("wrote %s (%d configurations)", out_png, len(picks))
