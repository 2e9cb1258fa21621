"""A component: one trainable network of a method, with its loss and its sampler, found by its kind.

A component of kind ``k`` is the class ``COMPONENT`` of the module ``tohgs.models.<k>`` (ContactDiffuser in
``tohgs/models/contact_diffuser.py``, GraspDiffuser in ``tohgs/models/grasp_diffuser.py``); its network
config is the dataclass ``COMPONENT.Config``, documented in the config schema under
``$defs.networks.<k>``. The config names components under ``components`` (a name, its kind, its network
and its training budget); one rule trains any of them (:func:`tohgs.models.train.train_component`) into
``results/models/<task>/<name>.pt`` (:mod:`tohgs.models.checkpoint`).

What a component does, every method on a :class:`tohgs.data.batch.Batch`:

- :meth:`Component.prepare` once before training (set what the data fixes: a normaliser, the hand);
- :meth:`Component.loss` per training step: a dict whose ``"loss"`` is optimised (other entries are logged;
  ``w_<term>`` entries are the weighted terms whose gradient shares are logged);
- a sampler for its role: ``sample_contact`` (a contact source: (B, N) maps) or ``sample_grasps`` (a grasp
  generator: (B, 51) grasps in the network frame, from a batch that carries contact maps).

Adding a network is one module with a ``COMPONENT`` and its schema block; the training loop, the
checkpoint and the rules do not change.
"""

from __future__ import annotations

import importlib
from typing import Any, ClassVar

import torch
from torch import nn

from tohgs.data.batch import Batch
from tohgs.models import component_kind_exists, component_kinds



class Component(nn.Module):
    """The interface of a trainable network (subclasses set ``kind`` and ``Config``)."""

    kind: ClassVar[str] = ""
    Config: ClassVar[type]
    #: What it samples, the ``x-role`` of its kind in the schema (``$defs.networks.<kind>``; a test keeps them
    #: equal): ``contact`` (``sample_contact``), ``grasp`` (``sample_grasps``), ``hand_contact``, ``pose_prior``.
    role: ClassVar[str] = ""
    needs_hand: ClassVar[bool] = False  # the loss poses the hand: training passes the hand model
    #: Its sampler takes scene-aware guidance (``steer``, :mod:`tohgs.models.guidance`).
    steerable: ClassVar[bool] = False

    @property
    def reads_contact(self) -> bool:
        """Whether its sampler reads the batch's contact maps (a grasp generator conditioned on them; its
        network config may say so): False unless the kind says otherwise."""
        return False

    @property
    def samples_parts(self) -> bool:
        """Whether it samples ContactGen's object-centric representation with parts and directions
        (``sample_representation``): False unless the kind says otherwise."""
        return False

    def prepare(self, data, task: str, hand=None) -> None:
        """Set what the training data fixes before the first step (``data``: a
        :class:`tohgs.data.maps.MapDataset` of the training grasps with the training augmentation; ``task``
        picks task-specific loss weights). The default does nothing."""

    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The training losses of one batch (``"loss"`` is optimised); draws from ``generator`` only."""
        raise NotImplementedError(f"{type(self).__name__} has no loss")


def component_class(kind: str) -> type[Component]:
    """The component class of ``kind`` (``tohgs.models.<kind>.COMPONENT``).

    Raises:
        ValueError: no such module, or it defines no component.
    """
    if not component_kind_exists(kind):
        raise ValueError(f"unknown component kind {kind!r} (known: {', '.join(component_kinds())})")
    cls = getattr(importlib.import_module(f"tohgs.models.{kind}"), "COMPONENT", None)
    if cls is None or not issubclass(cls, Component):
        raise ValueError(f"tohgs/models/{kind}.py defines no COMPONENT (a tohgs.models.component.Component)")
    return cls


def build_component(kind: str, network: dict[str, Any]) -> Component:
    """A fresh, untrained component of ``kind`` from its network config mapping."""
    cls = component_class(kind)
    return cls(cls.Config.from_dict(network))


def seen_grasps(model: Component, data, device: torch.device, min_samples: int = 4096, max_draws: int = 8
                ) -> torch.Tensor:
    """(G', D) the training grasps as the network sees them: augmented as in training (draws 0, 1, ...
    of every item of the :class:`tohgs.data.maps.MapDataset` ``data``, until ``min_samples`` or
    ``max_draws``) and in the network's frame (``model.in_frame(grasp, points, contact, normals)``). A grasp
    normaliser is computed on these, not on the stored grasps, whose rotation the augmentation changes."""
    draws = 1 if data.rotation == "none" else min(max_draws, max(1, -(-min_samples // len(data))))
    out = []
    with torch.no_grad():
        for draw in range(draws):
            items = [data.item(i, draw) for i in range(len(data))]
            for k in range(0, len(items), 256):
                chunk = Batch.collate(items[k:k + 256], device)
                out.append(model.in_frame(chunk.grasp, chunk.points, chunk.contact, chunk.normals))
    return torch.cat(out)
