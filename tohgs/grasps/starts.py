"""Start hands near an object: relaxed hands turned at random with the palm on a random object point, as a
coarse generator's grasps land (partly inside the object). The optimisers' tests and benchmarks start from
them (tests/test_batched.py, tests/test_opt_speed.py, benchmarks/bench_opt_speed.py).
"""

from __future__ import annotations

import torch

from tohgs.hand.model import HandModel


def near_object(hand: HandModel, points: torch.Tensor, n: int, seed: int) -> torch.Tensor:
    """(n, 51) relaxed hands with the palm near the object's surface, turned at random.

    Args:
        hand: the hand model (its ``relaxed`` preset and palm vertices).
        points: (N, 3) object surface points, m, in the frame the hands are wanted in.
        n: how many hands.
        seed: seeds the draws (the turns, 0.4 rad standard deviation per axis-angle number, then the points).

    Returns:
        (n, 51) grasps (translation m, axis-angles rad) whose palm centres sit on ``n`` of the points.
    """
    gen = torch.Generator().manual_seed(seed)
    g = hand.preset("relaxed", n).clone()
    g[:, 3:6] += 0.4 * torch.randn(n, 3, generator=gen)
    with torch.no_grad():
        palm = hand(g).vertices[:, hand.assets.palm_ids].mean(1)
    g[:, :3] += points[torch.randint(0, len(points), (n,), generator=gen)] - palm
    return g
