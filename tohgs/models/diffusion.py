"""Diffusion plumbing shared by both diffusers: schedulers from the ``diffusers`` library, the timestep
embedding, and the reverse-process sampling loop (full DDPM or DDIM with k steps).

Schedules and samplers are diffusers' ``DDPMScheduler`` / ``DDIMScheduler`` (linear betas, T = 1000 for
training), not hand-written: they are tested upstream, and the same scheduler object serves training
(``add_noise``) and sampling (``step``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import torch
from torch import nn


@dataclass(frozen=True)
class DiffusionConfig:
    """Noise schedule and prediction target.

    Attributes:
        timesteps: T of training (the paper's 1000).
        beta_start, beta_end: the linear beta schedule (ContactDiffuser 1e-4..0.02, GraspDiffuser 1e-4..0.01).
        prediction: ``"epsilon"`` (ContactDiffuser) or ``"sample"`` (x0, GraspDiffuser).
        clip: clamp x0 estimates to [-clip, clip] while sampling (0: no clamp).
    """

    timesteps: int = 1000
    beta_start: float = 1e-4
    beta_end: float = 0.02
    prediction: str = "epsilon"
    clip: float = 1.0


def make_scheduler(cfg: DiffusionConfig, sampler: str = "ddpm"):
    """A diffusers scheduler for ``cfg``: ``"ddpm"`` (ancestral, every step) or ``"ddim"`` (eta 0)."""
    from diffusers import DDIMScheduler, DDPMScheduler

    kw = dict(num_train_timesteps=cfg.timesteps, beta_start=cfg.beta_start, beta_end=cfg.beta_end,
              beta_schedule="linear", prediction_type=cfg.prediction, clip_sample=cfg.clip > 0,
              clip_sample_range=cfg.clip if cfg.clip > 0 else 1.0)
    if sampler == "ddpm":
        return DDPMScheduler(**kw)
    if sampler == "ddim":
        return DDIMScheduler(**kw)
    raise ValueError(f"sampler must be 'ddpm' or 'ddim', not {sampler!r}")


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """(B, dim) sinusoidal embedding of (B,) integer timesteps."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=t.device, dtype=torch.float32) / half)
    args = t.float()[:, None] * freqs[None]
    emb = torch.cat([torch.cos(args), torch.sin(args)], -1)
    return torch.nn.functional.pad(emb, (0, dim % 2))


class TimeMLP(nn.Module):
    """Sinusoidal embedding followed by a two-layer MLP: (B,) -> (B, dim)."""

    def __init__(self, dim: int):
        super().__init__()
        self.dim = dim
        self.net = nn.Sequential(nn.Linear(dim, 4 * dim), nn.SiLU(), nn.Linear(4 * dim, dim))

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        return self.net(timestep_embedding(t, self.dim))


@torch.no_grad()
def sample(denoise: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], shape: tuple[int, ...], cfg: DiffusionConfig,
           sampler: str = "ddpm", steps: int | None = None, generator: torch.Generator | None = None,
           device: str | torch.device = "cpu") -> torch.Tensor:
    """Run the reverse process from Gaussian noise.

    Args:
        denoise: ``f(x_t, t) -> model output`` (epsilon or x0, as ``cfg.prediction``); ``t`` is (B,) long.
        shape: the sample's shape, batch first.
        cfg: the noise schedule the model was trained with.
        sampler: ``"ddpm"`` (all T steps unless ``steps``) or ``"ddim"`` (``steps`` steps, eta 0).
        steps: inference steps (default: T for DDPM, 100 for DDIM).
        generator: CPU generator for the initial noise and DDPM's noise (reproducible samples).

    Returns:
        The denoised sample x_0 (shape ``shape``).
    """
    sched = make_scheduler(cfg, sampler)
    n = steps if steps is not None else (cfg.timesteps if sampler == "ddpm" else 100)
    sched.set_timesteps(n)
    x = torch.randn(shape, generator=generator).to(device)
    for t in sched.timesteps:
        tt = torch.full((shape[0],), int(t), dtype=torch.long, device=device)
        out = denoise(x, tt)
        if sampler == "ddpm":
            noise = torch.randn(shape, generator=generator).to(device)
            x = _ddpm_with_noise(sched, out, int(t), x, noise)
        else:
            x = sched.step(out, int(t), x, eta=0.0, return_dict=True).prev_sample
    return x


def _ddpm_with_noise(sched, model_output: torch.Tensor, t: int, x: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
    """DDPM's ancestral step (the posterior mean of DDPM's eq. 7 plus its variance, diffusers'
    "fixed_small") with a given noise draw: the scheduler's own ``step`` draws from torch's global RNG,
    which would make samples depend on unrelated code. Uses the scheduler's alphas and timestep spacing."""
    prev_t = sched.previous_timestep(t)
    a_t = sched.alphas_cumprod[t]
    if sched.config.prediction_type == "epsilon":
        pred = (x - (1 - a_t).sqrt() * model_output) / a_t.sqrt()
    else:
        pred = model_output
    if sched.config.clip_sample:
        r = sched.config.clip_sample_range
        pred = pred.clamp(-r, r)
    a_prev = sched.alphas_cumprod[prev_t] if prev_t >= 0 else sched.one
    beta_t = 1 - a_t / a_prev
    c0 = a_prev.sqrt() * beta_t / (1 - a_t)
    ct = (a_t / a_prev).sqrt() * (1 - a_prev) / (1 - a_t)
    mean = c0 * pred + ct * x
    if t > 0:
        var = ((1 - a_prev) / (1 - a_t) * beta_t).clamp_min(1e-20)
        mean = mean + var.sqrt() * noise
    return mean
