"""Kind ``contact_gen``: ContactGen (Liu et al. ICCV 2023; paper section 5.1): S object-centric
representations sampled from the sequential CVAE (:mod:`tohgs.models.contact_gen`, with parts), then the
grasp of each from its solver (:mod:`tohgs.grasps.contactgen_solver`).

Key of the method block: ``model``, a ContactGen component with parts (``parts: true``), or
``ground_truth``: the representation the configuration's own task grasps make on its points (the same
grasps the ``Dataset`` row evaluates, :func:`tohgs.methods.base.ground_truth_pick`), which checks the solver
apart from the generator (the ground-truth gate: the solver should come close to the Dataset row). The prediction
setting ``contactgen`` (:class:`tohgs.grasps.contactgen_solver.SolverSettings`) is this kind's; the
representations of ``chunk`` configurations are solved as one batch (the same grasps as one at a time). The
stored contact maps are the sampled representations' contact; per configuration the mean solver energy
at the end is recorded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields

import numpy as np
import torch

from tohgs.geometry.contact_parts import PartContact
from tohgs.grasps.contactgen_solver import SolverSettings, representation_of, solve_many
from tohgs.methods import GROUND_TRUTH
from tohgs.methods.base import Method, Prediction, Request, SamplingSettings
from tohgs.settings import block


@dataclass(frozen=True)
class ContactGenSettings(SamplingSettings):
    """Every job's settings and ``contactgen``, the solver's
    (:class:`tohgs.grasps.contactgen_solver.SolverSettings`)."""

    contactgen: SolverSettings = block(SolverSettings)


class ContactGenMethod(Method):
    """Sampled representations, then the solver (module docstring)."""

    Settings = ContactGenSettings

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.require_hand("ContactGen's solver poses hands")
        self.generator = None if self.cfg["model"] == GROUND_TRUTH else self.model("model")
        if self.generator is not None and not self.generator.samples_parts:
            raise ValueError(f"method {self.name!r}: its model {self.cfg['model']!r} samples no parts and directions "
                             "(a contact_gen component with parts: true)")
        self.solver = self.settings.contactgen

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        return self.predict_many([Request(batch, shard, row, generator, rng)])[0]

    def _representation(self, r: Request) -> PartContact | None:
        """The (S, N) representations of one configuration: sampled from its stream, or its ground-truth
        grasps' (None for a configuration without task grasps)."""
        if self.generator is not None:
            return self.generator.sample_representation(r.batch, r.generator)
        ids = self.ground_truth(r.shard, r.row, r.batch.size)
        if len(ids) == 0:
            return None
        grasp = torch.as_tensor(r.shard.grasp[ids], dtype=r.batch.points.dtype, device=r.batch.device)
        return representation_of(self.hand, grasp, r.batch.points, r.shard.alpha_contact)

    def predict_many(self, requests: list[Request]) -> list[Prediction | None]:
        """Per configuration (its own stream, in order) the sampled (or ground-truth) representations; then
        the solver on every configuration's representations as one batch
        (:func:`tohgs.grasps.contactgen_solver.solve_many`); the solver's time is shared equally among the
        configurations. A configuration without a representation (ground truth without task grasps) is None."""
        reps, seconds = [], []
        for r in requests:
            t0 = time.perf_counter()
            reps.append(self._representation(r))
            seconds.append(time.perf_counter() - t0)
        out: list[Prediction | None] = [None] * len(requests)
        have = [i for i, rep in enumerate(reps) if rep is not None]
        if not have:
            return out
        requests, reps, seconds = [requests[i] for i in have], [reps[i] for i in have], [seconds[i] for i in have]
        sizes = [len(rep.contact) for rep in reps]
        target = PartContact(*(torch.cat([getattr(rep, f.name) for rep in reps]) for f in fields(PartContact)))
        t1 = time.perf_counter()
        grasp, histories = solve_many(self.hand, torch.cat([r.batch.points for r in requests]), target, self.solver, sizes)
        share = (time.perf_counter() - t1) / len(requests)
        for i, rep, g, history, sec in zip(have, reps, grasp.split(sizes), histories, seconds):
            out[i] = Prediction(rep.contact.cpu().numpy().astype(np.float32), g.cpu().numpy().astype(np.float64),
                                {"representation": sec, "solver": share},
                                info={"energy_end": history["energy"][-1] if history else float("nan")})
        return out


METHOD = ContactGenMethod
