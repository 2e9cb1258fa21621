"""Kind ``contact_gen``: ContactGen (Liu et al. ICCV 2023; paper section 5.1): S object-centric
representations sampled from the sequential CVAE (:mod:`tohgs.models.contact_gen`, with parts), then the
grasp of each from its solver (:mod:`tohgs.grasps.contactgen_solver`).

Key of the method block: ``model``, a ContactGen component with parts (``parts: true``). The prediction
setting ``contactgen`` (:class:`tohgs.grasps.contactgen_solver.SolverSettings`) is this kind's. The
stored contact maps are the sampled representations' contact; per configuration the mean solver energy
at the end is recorded.
"""

from __future__ import annotations

import time

import numpy as np

from tohgs.config import settings_from
from tohgs.grasps.contactgen_solver import SolverSettings, solve
from tohgs.methods.base import Method, Prediction


class ContactGenMethod(Method):
    """Sampled representations, then the solver (module docstring)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.require_hand("ContactGen's solver poses hands")
        self.generator = self.model("model")
        if not getattr(getattr(self.generator, "cfg", None), "parts", False):
            raise ValueError(f"method {self.name!r}: its model {self.cfg['model']!r} samples no parts and directions "
                             "(a contact_gen component with parts: true)")
        self.solver = settings_from(SolverSettings, self.settings.contactgen)

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        t0 = time.perf_counter()
        rep = self.generator.sample_representation(batch, generator)
        t1 = time.perf_counter()
        grasp, history = solve(self.hand, batch.points, rep, self.solver)
        t2 = time.perf_counter()
        return Prediction(rep.contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                          {"representation": t1 - t0, "solver": t2 - t1},
                          info={"energy_end": history["energy"][-1] if history else float("nan")})


METHOD = ContactGenMethod
