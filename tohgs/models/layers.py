"""Small layers the networks share (no component kind: it binds no ``COMPONENT``).

:func:`mlp` is the one multilayer perceptron of GraspCVAE, ContactNet, ContactGen's stages, the pose prior
and PointNet / PointNet++'s shared per-point MLPs: it acts on the last axis, so (B, F) vectors and (B, N, F)
per-point features alike.
"""

from __future__ import annotations

from torch import nn


def mlp(sizes: list[int], last_plain: bool = True) -> nn.Sequential:
    """Linear layers ``sizes[0] -> sizes[1] -> ... -> sizes[-1]`` with LayerNorm + GELU after each (none after
    the last when ``last_plain``: a plain linear output). (..., sizes[0]) -> (..., sizes[-1])."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if not (last_plain and i == len(sizes) - 2):
            layers += [nn.LayerNorm(b), nn.GELU()]
    return nn.Sequential(*layers)
