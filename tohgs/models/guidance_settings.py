"""The settings of scene-aware guided sampling (:mod:`tohgs.models.guidance`), without torch: the settings
of contact_grasp's ``steer`` block, which a job is given only when it is set (its schema block's
``x-optional``: :func:`tohgs.config.job_settings`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class GuidanceSettings:
    """How guided sampling steers (module docstring).

    Attributes:
        scale: length of the normalised step on x0 per guided denoising step (network units); 0: none.
        start: guide the steps with ``t <= start * T`` (1: every step).
        w_scene, w_object, w_contact, w_joints: the terms' weights.
        margin: clearance the scene term asks for, m.
        max_depth: deeper penetrations are not counted (cloud edges), m.
        alpha: the contact map's sharpness (the maps' alpha, 1/m).
        hand_points: vertices used by the penetration terms (evenly spread; 0: all).
        contact_scale: length of the normalised step on ContactDiffuser's x0 per guided step; 0: none.
        near: object points closer to the scene than this at either pose are steered off, m.
        candidates: grasps sampled per kept grasp (1: no selection).
        pool: the lowest-energy fraction of the candidates the diverse pick chooses from.
    """

    scale: float = 0.0
    start: float = 0.5
    w_scene: float = 1.0
    w_object: float = 1.0
    w_contact: float = 0.0
    w_joints: float = 0.0
    margin: float = 0.005
    max_depth: float = 0.05
    alpha: float = 100.0  # tohgs.geometry.maps.ALPHA_CONTACT (the parse imports this module: no numpy; a test pins it)
    hand_points: int = 0
    contact_scale: float = 0.0
    near: float = 0.02
    candidates: int = 1
    pool: float = 0.5

    def __post_init__(self):
        if self.scale < 0 or not 0 <= self.start <= 1:
            raise ValueError(f"guidance needs scale >= 0 and start in [0, 1], got {self.scale}, {self.start}")
        if min(self.weights.values()) < 0:
            raise ValueError(f"guidance weights must be non-negative, got {self.weights}")
        if self.margin < 0 or self.max_depth <= 0 or self.alpha <= 0 or self.hand_points < 0:
            raise ValueError("guidance needs margin >= 0, max_depth > 0, alpha > 0 and hand_points >= 0")
        if self.contact_scale < 0 or self.near <= 0 or self.candidates < 1 or not 0 < self.pool <= 1:
            raise ValueError(f"guidance needs contact_scale >= 0, near > 0, candidates >= 1 and pool in (0, 1], got "
                             f"{self.contact_scale}, {self.near}, {self.candidates}, {self.pool}")

    @property
    def weights(self) -> dict[str, float]:
        return {"scene": self.w_scene, "object": self.w_object, "contact": self.w_contact, "joints": self.w_joints}

    @property
    def active(self) -> bool:
        """Whether guidance changes anything (a positive scale and a positive weight)."""
        return self.scale > 0 and self.start > 0 and max(self.weights.values()) > 0

    @property
    def contact_active(self) -> bool:
        """Whether ContactDiffuser's sampling is guided (a positive ``contact_scale`` and ``start``)."""
        return self.contact_scale > 0 and self.start > 0

    @property
    def selects(self) -> bool:
        """Whether more grasps are sampled than kept (``candidates > 1``)."""
        return self.candidates > 1
