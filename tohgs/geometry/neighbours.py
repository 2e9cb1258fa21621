"""Nearest neighbours within one point cloud (torch, all pairs): the kNN graph that ContactDiffuser's local
mixing, the methods' contact smoothing and the models' map-roughness check read.

Shapes: points (B, N, 3) m; indices (B, N, k) into the same N points.
"""

from __future__ import annotations

import torch


def nearest_neighbours(points: torch.Tensor, k: int) -> torch.Tensor:
    """(B, N, k) indices of each of (B, N, 3) points' k nearest other points (Euclidean; a point is never its
    own neighbour), nearest first. ``k`` at most N - 1."""
    d = torch.cdist(points, points)
    d.diagonal(dim1=1, dim2=2).fill_(float("inf"))
    return d.topk(k, dim=-1, largest=False).indices
