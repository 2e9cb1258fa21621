"""Diffusion plumbing shared by both diffusers: the noise schedule, the timestep embedding, and the
reverse-process sampling loop (full DDPM or DDIM with k steps).

:class:`NoiseSchedule` is DDPM's linear-beta schedule (T = 1000 for training), computed in float64 and kept
as float32 tensors, with the forward process (``q_sample``) and the two reverse steps: DDPM's ancestral
step (posterior variance "fixed small") and DDIM's deterministic step (eta 0). Timesteps are spaced as
diffusers' ``DDPMScheduler`` / ``DDIMScheduler`` space them ("leading", the final step to alpha-bar 1), and
the tests check every step against those schedulers when diffusers is installed. The library is not a
runtime dependency: importing it costs about 4 s (7 s with its EMA helper) in every training and
prediction job.
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


class NoiseSchedule:
    """DDPM's linear-beta schedule and its forward and reverse steps.

    Attributes:
        cfg: the :class:`DiffusionConfig`.
        betas, alphas_cumprod: (T,) float32 (computed in float64): beta_t and alpha-bar_t.
    """

    def __init__(self, cfg: DiffusionConfig):
        if cfg.prediction not in ("epsilon", "sample"):
            raise ValueError(f"prediction must be 'epsilon' or 'sample', not {cfg.prediction!r}")
        self.cfg = cfg
        betas = torch.linspace(cfg.beta_start, cfg.beta_end, cfg.timesteps, dtype=torch.float64)
        self.betas = betas.float()
        self.alphas_cumprod = torch.cumprod(1.0 - betas, 0).float()

    @property
    def timesteps(self) -> int:
        """T, the number of training timesteps."""
        return self.cfg.timesteps

    def alpha_bar(self, t: int) -> torch.Tensor:
        """alpha-bar_t as a 0-d tensor; 1 for t < 0 (the clean end of the chain)."""
        return self.alphas_cumprod[t] if t >= 0 else torch.tensor(1.0)

    def q_sample(self, x0: torch.Tensor, noise: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """x_t = sqrt(alpha-bar_t) x0 + sqrt(1 - alpha-bar_t) noise for (B, ...) x0, noise and (B,) long t."""
        a = self.alphas_cumprod.to(x0.device)[t].to(x0.dtype).reshape((-1,) + (1,) * (x0.ndim - 1))
        return a.sqrt() * x0 + (1 - a).sqrt() * noise

    def inference_timesteps(self, steps: int) -> list[int]:
        """The ``steps`` timesteps of a reverse pass, descending: ``k * (T // steps)`` for k < steps."""
        if not 1 <= steps <= self.timesteps:
            raise ValueError(f"steps must be in 1..{self.timesteps}, not {steps}")
        ratio = self.timesteps // steps
        return [k * ratio for k in reversed(range(steps))]

    def predict_x0_eps(self, model_output: torch.Tensor, t: int, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The network's x0 and epsilon estimates at x_t (x0 clamped to [-clip, clip] when ``clip`` > 0;
        epsilon is the unclamped one)."""
        a_t = self.alpha_bar(t)
        if self.cfg.prediction == "epsilon":
            eps = model_output
            x0 = (x - (1 - a_t).sqrt() * eps) / a_t.sqrt()
        else:
            x0 = model_output
            eps = (x - a_t.sqrt() * x0) / (1 - a_t).sqrt()
        if self.cfg.clip > 0:
            x0 = x0.clamp(-self.cfg.clip, self.cfg.clip)
        return x0, eps

    def ddpm_step(self, model_output: torch.Tensor, t: int, prev_t: int, x: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """DDPM's ancestral step x_t -> x_prev_t: the posterior mean (DDPM's eq. 7) plus the "fixed small"
        posterior standard deviation times ``noise`` (none at t = 0). ``noise`` is the caller's draw, so
        samples depend only on the caller's generator."""
        x0, _ = self.predict_x0_eps(model_output, t, x)
        a_t, a_prev = self.alpha_bar(t), self.alpha_bar(prev_t)
        beta_t = 1 - a_t / a_prev
        mean = a_prev.sqrt() * beta_t / (1 - a_t) * x0 + (a_t / a_prev).sqrt() * (1 - a_prev) / (1 - a_t) * x
        if t > 0:
            mean = mean + ((1 - a_prev) / (1 - a_t) * beta_t).clamp_min(1e-20).sqrt() * noise
        return mean

    def ddim_step(self, model_output: torch.Tensor, t: int, prev_t: int, x: torch.Tensor) -> torch.Tensor:
        """DDIM's deterministic step (eta 0): x_prev = sqrt(a_prev) x0 + sqrt(1 - a_prev) eps."""
        x0, eps = self.predict_x0_eps(model_output, t, x)
        a_prev = self.alpha_bar(prev_t)
        return a_prev.sqrt() * x0 + (1 - a_prev).sqrt() * eps


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
           device: str | torch.device = "cpu",
           guide: Callable[[torch.Tensor, torch.Tensor], torch.Tensor | None] | None = None) -> torch.Tensor:
    """Run the reverse process from Gaussian noise.

    Args:
        denoise: ``f(x_t, t) -> model output`` (epsilon or x0, as ``cfg.prediction``); ``t`` is (B,) long.
        shape: the sample's shape, batch first.
        cfg: the noise schedule the model was trained with.
        sampler: ``"ddpm"`` (all T steps unless ``steps``) or ``"ddim"`` (``steps`` steps, eta 0).
        steps: inference steps (default: T for DDPM, 100 for DDIM).
        generator: CPU generator for the initial noise and DDPM's noise (reproducible samples).
        guide: ``g(x0, t) -> delta`` or None, asked at every step with the network's x0 estimate: the step
            then continues as if the estimate were ``x0 - delta`` with the same noise estimate, i.e. the
            sample moves by ``-sqrt(alpha-bar_prev) delta`` (the way DDIM carries its x0 estimate; the
            last step returns ``x0 - delta``). None (or a None answer): the plain step, bit for bit.

    Returns:
        The denoised sample x_0 (shape ``shape``).
    """
    if sampler not in ("ddpm", "ddim"):
        raise ValueError(f"sampler must be 'ddpm' or 'ddim', not {sampler!r}")
    sched = NoiseSchedule(cfg)
    n = steps if steps is not None else (cfg.timesteps if sampler == "ddpm" else 100)
    ts = sched.inference_timesteps(n)
    ratio = cfg.timesteps // n
    x = torch.randn(shape, generator=generator).to(device)
    for t in ts:
        tt = torch.full((shape[0],), t, dtype=torch.long, device=device)
        out = denoise(x, tt)
        delta = None if guide is None else guide(sched.predict_x0_eps(out, t, x)[0], tt)
        if sampler == "ddpm":
            noise = torch.randn(shape, generator=generator).to(device)
            x = sched.ddpm_step(out, t, t - ratio, x, noise)
        else:
            x = sched.ddim_step(out, t, t - ratio, x)
        if delta is not None:
            x = x - sched.alpha_bar(t - ratio).to(x).sqrt() * delta
    return x
