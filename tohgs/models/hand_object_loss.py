"""The hand-object loss terms that GraspDiffuser and GraspCVAE both train with (the official code's; their
one home), and the per-sample clamped weighting of the penetration term.

Per sample, for a predicted hand (its vertices posed by the hand model) against the true hand on the object
cloud with the true hand's contact map ``c``:

- ``L_recon``: squared distance of the predicted hand's vertices to the true hand's, summed over the
  vertices (m^2);
- ``L_pen``: object points inside the predicted hand (behind their nearest hand vertex's normal),
  ``100 sum d^2 (1 + 3 (1 - c))``, d the offset to that vertex (m);
- ``L_cons``: contact-map consistency ``sum (C'(pred hand) - c)^2 (1 + 5 c)``, C' the predicted hand's map.

The two point sums are scaled to the paper's 2048 points (``sum x (2048 / N)``), so that the paper's weights
mean the same with any number of training points. In the loss ``L_pen`` enters as ``mean_b min(L_pen, 1)``:
the clamp acts per sample, so a batch with one far-off hand keeps the gradient of the others.

Shapes: points (B, N, 3) m, hand vertices (B, V, 3) m, closed faces (F, 3), contact maps (B, N) in [0, 1].
"""

from __future__ import annotations

import torch

from tohgs.geometry.hand_object import contact_values, inside_hand, vertex_normals

PAPER_POINTS = 2048  # the point sums of L_pen and L_cons are scaled to this many points


def hand_object_terms(points: torch.Tensor, pred_v: torch.Tensor, true_v: torch.Tensor, contact: torch.Tensor,
                      closed_faces: torch.Tensor, alpha_contact: float) -> dict[str, torch.Tensor]:
    """The per-sample (B,) terms ``recon``, ``pen`` and ``cons`` (module docstring; unweighted, unclamped).

    Args:
        points: (B, N, 3) object points, m (the frame the hands are posed in).
        pred_v: (B, V, 3) the predicted hands' vertices, m.
        true_v: (B, V, 3) the true hands' vertices, m.
        contact: (B, N) the true hands' contact maps, in [0, 1].
        closed_faces: (F, 3) the hand's closed mesh faces (its vertex normals decide what is inside).
        alpha_contact: the contact map's sharpness, 1/m.
    """
    scale = PAPER_POINTS / points.shape[1]
    l_recon = ((pred_v - true_v) ** 2).sum((-1, -2))
    c_pred, idx = contact_values(points, pred_v, alpha_contact)
    inside, offset = inside_hand(points, pred_v, vertex_normals(pred_v, closed_faces), idx)
    l_pen = 100.0 * scale * (inside * (offset**2).sum(-1) * (1 + 3 * (1 - contact))).sum(-1)
    l_cons = scale * ((c_pred - contact) ** 2 * (1 + 5 * contact)).sum(-1)
    return {"recon": l_recon, "pen": l_pen, "cons": l_cons}


def weighted_pen_cons(terms: dict[str, torch.Tensor], w_pen: float, w_cons: float) -> dict[str, torch.Tensor]:
    """The penetration and consistency terms' contributions to the loss (scalars): ``w_pen mean_b min(L_pen,
    1)`` (clamped per sample) and ``w_cons mean_b L_cons``, from (B,) ``terms["pen"]`` and ``terms["cons"]``."""
    return {"pen": w_pen * terms["pen"].clamp(max=1.0).mean(), "cons": w_cons * terms["cons"].mean()}
