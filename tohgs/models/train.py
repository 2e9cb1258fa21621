"""One training loop for every component (:mod:`tohgs.models.component`) on map shards: AdamW, cosine
schedule with warm-up, EMA weights, a fixed seed, progress in the log, resumable.

The loop knows nothing of the network: it draws batches (:class:`tohgs.data.batch.Batch`), asks the
component for its loss and steps the optimiser. The checkpoint ``results/models/<task>/<component>.pt``
is :mod:`tohgs.models.checkpoint`'s format. While training, a resume file ``<checkpoint>.resume`` is
written every ``checkpoint_every`` steps (model, EMA, optimiser, schedule, RNG state and step); a
restarted job continues from it, and it is removed at the end.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tohgs.data.batch import Batch
from tohgs.data.maps import MapDataset
from tohgs.hand.model import HandModel
from tohgs.io import atomic_path, content_key
from tohgs.models.checkpoint import load_checkpoint, pick_device, save_checkpoint
from tohgs.models.component import build_component
from tohgs.settings import settings_from

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainSettings:
    """Optimiser and schedule (the official code's: AdamW lr 5e-4, betas (0.95, 0.999), wd 1e-5, cosine
    with 500 warm-up steps); ``steps`` replaces epochs so the budget is explicit. The defaults are the
    config schema's ``training`` block (a test keeps them equal)."""

    steps: int = 1000
    batch: int = 16
    lr: float = 5e-4
    betas: tuple[float, float] = (0.95, 0.999)
    weight_decay: float = 1e-5
    warmup: int = 100
    ema_decay: float = 0.995
    rotation: str = "so3"
    rotation_max: float = 0.5236  # rad: the largest turn of rotation "bounded" (ContactGen's 30 degrees)
    checkpoint_every: int = 250
    log_every: int = 50
    seed: int = 0
    threads: int = 1
    device: str = "auto"
    train_points: int = 256  # a random subset of the N points per batch (0: all); the networks are per point
    clip_grad: float = 1.0  # the gradient's norm is clipped to this (0: no clipping, the official diffusers)


def cosine_with_warmup(optimizer: torch.optim.Optimizer, warmup: int, total: int) -> torch.optim.lr_scheduler.LambdaLR:
    """Learning-rate factor rising linearly from 0 over ``warmup`` steps, then half a cosine down to 0 at
    ``total`` (the official code's schedule; diffusers' ``get_cosine_schedule_with_warmup``)."""

    def factor(step: int) -> float:
        if step < warmup:
            return step / max(1, warmup)
        progress = (step - warmup) / max(1, total - warmup)
        return max(0.0, 0.5 * (1.0 + math.cos(math.pi * progress)))

    return torch.optim.lr_scheduler.LambdaLR(optimizer, factor)


class EMA:
    """Exponential moving average of a model's parameters (diffusers' ``EMAModel`` rule): update k = 1, 2, ...
    uses decay 0 for k = 1 and ``min(decay, k / (9 + k))`` after, so the average starts at the weights and
    forgets the early ones quickly."""

    def __init__(self, parameters, decay: float):
        self.decay = float(decay)
        self.step_count = 0
        self.shadow = [p.detach().clone() for p in parameters]

    def current_decay(self) -> float:
        """The decay of the update that was made last."""
        k = self.step_count - 1
        return 0.0 if k <= 0 else min(self.decay, (1 + k) / (10 + k))

    @torch.no_grad()
    def step(self, parameters) -> None:
        self.step_count += 1
        d = self.current_decay()
        for s, p in zip(self.shadow, parameters):
            if p.requires_grad:
                s.sub_((1 - d) * (s - p))
            else:
                s.copy_(p)

    @torch.no_grad()
    def copy_to(self, parameters) -> None:
        """Write the averaged weights into ``parameters``."""
        for s, p in zip(self.shadow, parameters):
            p.copy_(s)

    def state_dict(self) -> dict[str, Any]:
        return {"decay": self.decay, "step_count": self.step_count, "shadow": self.shadow}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.decay, self.step_count = float(state["decay"]), int(state["step_count"])
        self.shadow = [t.clone() for t in state["shadow"]]


def gradient_shares(model: torch.nn.Module, losses: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The gradient norm of each weighted loss term (``w_<term>``) over the model's parameters, as
    ``grad_<term>``: how much each term pulls, where the loss values alone do not say (a clamped term has
    a value and no gradient)."""
    params = [p for p in model.parameters() if p.requires_grad]
    out = {}
    for k in [k for k in losses if k.startswith("w_")]:
        grads = torch.autograd.grad(losses[k], params, retain_graph=True, allow_unused=True)
        out[f"grad_{k[2:]}"] = torch.sqrt(sum((g.detach() ** 2).sum() for g in grads if g is not None))
    return out


def train_component(component: str, kind: str, task: str, shard_paths: list[str | Path], network: dict[str, Any],
                    settings: dict[str, Any], out: str | Path, hand: HandModel | None = None,
                    curve_png: str | Path | None = None) -> dict[str, Any]:
    """Train the component ``component`` of ``kind`` for ``task`` on the training shards; write its
    checkpoint ``out`` (and the loss curve ``curve_png``).

    Args:
        component: the config's name of the component (recorded; the run key includes it).
        kind: its kind (:func:`tohgs.models.component.component_class`).
        task: the task (some losses weight their terms per task).
        shard_paths: the task's training map shards.
        network: the network config mapping (the kind's ``Config``).
        settings: a mapping of :class:`TrainSettings`.
        hand: the hand model, for a component whose loss poses the hand (``needs_hand``).

    Returns:
        The checkpoint dict.
    """
    s = settings_from(TrainSettings, settings)
    torch.set_num_threads(max(1, s.threads))
    device = pick_device(s.device)
    torch.manual_seed(s.seed)
    data = MapDataset(shard_paths, per="grasp", rotation=s.rotation, seed=s.seed, rotation_max=s.rotation_max)
    if len(data) == 0:
        raise ValueError(f"{task}/{component}: the training shards {list(map(str, shard_paths))} hold no task grasps")
    model = build_component(kind, network).to(device)
    if model.needs_hand:
        if hand is None:
            raise ValueError(f"{task}/{component}: {type(model).__name__} trains with the hand model in the loss; pass hand=")
        hand = hand.to(device)
    model.prepare(data, task, hand)
    opt = torch.optim.AdamW(model.parameters(), lr=s.lr, betas=s.betas, weight_decay=s.weight_decay)
    lr_sched = cosine_with_warmup(opt, s.warmup, s.steps)
    ema = EMA(model.parameters(), decay=s.ema_decay)
    gen = torch.Generator().manual_seed(s.seed)
    order_rng = np.random.default_rng(s.seed)
    curve: list[dict[str, float]] = []
    step, spent = 0, 0.0
    resume = Path(str(out) + ".resume")
    key = run_key(kind, task, network, s, data)
    state = _load_resume(resume, key, device)
    if state is not None:
        model.load_state_dict(state["model"])
        ema.load_state_dict(state["ema"])
        opt.load_state_dict(state["opt"])
        lr_sched.load_state_dict(state["lr_sched"])
        gen.set_state(state["gen"])
        order_rng.bit_generator.state = state["order_rng"]
        step, curve, spent = state["step"], state["curve"], state["spent"]
        log.info("%s/%s: resuming at step %d from %s", task, component, step, resume)
    n_params = sum(p.numel() for p in model.parameters())
    log.info("%s/%s (%s): %d parameters, %d training grasps, %d steps of batch %d on %s", task, component, kind,
             n_params, len(data), s.steps, s.batch, device)
    t0 = time.perf_counter()
    running: dict[str, tuple[float, int]] = {}  # sum and count of each logged value since the last row
    n_pts = data.shards[0].points.shape[1]
    model.train()
    while step < s.steps:
        idx = order_rng.integers(0, len(data), s.batch)
        keep = order_rng.permutation(n_pts)[: s.train_points] if 0 < s.train_points < n_pts else None
        batch = Batch.collate([data.item(int(i), step) for i in idx], device, keep)
        losses = model.loss(batch, gen)
        opt.zero_grad(set_to_none=True)
        if (step + 1) % s.log_every == 0 and any(k.startswith("w_") for k in losses):
            losses.update(gradient_shares(model, losses))
        losses["loss"].backward()
        if s.clip_grad > 0:
            torch.nn.utils.clip_grad_norm_(model.parameters(), s.clip_grad)
        opt.step()
        lr_sched.step()
        ema.step(model.parameters())
        step += 1
        for k, v in losses.items():
            total, count = running.get(k, (0.0, 0))
            running[k] = (total + float(v.detach()), count + 1)
        if step % s.log_every == 0 or step == s.steps:
            row = {"step": step, **{k: total / count for k, (total, count) in running.items()}, "lr": lr_sched.get_last_lr()[0]}
            curve.append(row)
            running = {}
            log.info("%s/%s step %d/%d: %s", task, component, step, s.steps,
                     ", ".join(f"{k} {v:.4g}" for k, v in row.items() if k != "step"))
        if step % s.checkpoint_every == 0 and step < s.steps:
            with atomic_path(resume) as tmp:
                torch.save({"key": key, "model": model.state_dict(), "ema": ema.state_dict(), "opt": opt.state_dict(),
                            "lr_sched": lr_sched.state_dict(), "gen": gen.get_state(),
                            "order_rng": order_rng.bit_generator.state, "step": step, "curve": curve,
                            "spent": spent + time.perf_counter() - t0}, tmp)
    spent += time.perf_counter() - t0
    ema.copy_to(model.parameters())
    ckpt = save_checkpoint(out, model, component, task, network, asdict(s), loss_curve=curve, seconds=spent,
                           n_parameters=n_params, n_train_grasps=len(data),
                           alpha_contact=data.shards[0].alpha_contact,
                           hand_wrist=data.shards[0].attrs["hand_wrist"])
    resume.unlink(missing_ok=True)
    if curve_png is not None:
        plot_curve(curve, f"{task} / {component}", curve_png)
    log.info("%s/%s: trained in %.1f s, final loss %.4g", task, component, spent, curve[-1]["loss"] if curve else float("nan"))
    return ckpt


_NOT_SHAPING = ("threads", "device", "log_every", "checkpoint_every")  # settings a resumed run may change


def run_key(kind: str, task: str, network: dict[str, Any], settings: TrainSettings, data: MapDataset) -> str:
    """What shapes a training run: the kind and its network, the settings that change its steps (not
    threads, device or logging) and the training data. A resume file of another key is not resumed."""
    shaping = {k: v for k, v in asdict(settings).items() if k not in _NOT_SHAPING}
    arrays = [sh.arrays[k] for sh in data.shards for k in ("grasp", "contact", "points", "d_init", "d_goal")]
    return content_key(kind, task, network, shaping, *arrays)


def _load_resume(resume: Path, key: str, device: torch.device) -> dict[str, Any] | None:
    """The state of ``resume`` if it exists and belongs to this run (``key``); a file of another run is
    removed (logged) so that training starts afresh."""
    if not resume.is_file():
        return None
    state = load_checkpoint(resume, map_location=device)
    if "step_count" not in state.get("ema", {}):
        raise ValueError(f"{resume}: a resume file of an older tohgs (diffusers' EMA state); delete it to "
                         "train from the start")
    if state.get("key") != key:
        log.warning("%s: written by a run with other settings or data (model, schedule, batch, seed or "
                    "shards changed); training from the start", resume)
        resume.unlink()
        return None
    return state


def plot_curve(curve: list[dict[str, float]], title: str, out_png: str | Path) -> None:
    """Training curves as a PNG: the loss and each weighted term's contribution to it (``w_*``), and,
    where logged, each term's gradient norm (``grad_*``: what each term pulls, a clamped term none)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in (curve[0] if curve else {}) if k not in ("step", "lr")]
    grads = [k for k in {k for r in curve for k in r} if k.startswith("grad_")]
    values = [k for k in keys if k == "loss" or k.startswith("w_")] or [k for k in keys if not k.startswith("grad_")]
    fig, axes = plt.subplots(1, 2 if grads else 1, figsize=(11 if grads else 6, 3.5), squeeze=False)
    steps = [r["step"] for r in curve]
    ax = axes[0, 0]
    for key in values:
        ax.plot(steps, [max(r[key], 1e-12) for r in curve], label=key)
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss and weighted terms")
    ax.set_title(title)
    ax.legend(fontsize=7)
    if grads:
        ax = axes[0, 1]
        for key in sorted(grads):
            rows = [r for r in curve if key in r]
            ax.plot([r["step"] for r in rows], [max(r[key], 1e-12) for r in rows], label=key, marker=".")
        ax.set_yscale("log")
        ax.set_xlabel("step")
        ax.set_ylabel("gradient norm of each weighted term")
        ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
