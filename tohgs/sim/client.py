"""One headless PyBullet client (DIRECT mode): connect, reset, close. The scenes' :class:`tohgs.sim.world.World`
and the simulation-displacement metric (:class:`tohgs.metrics.quality.DisplacementSimulator`) are built on it."""

from __future__ import annotations

from typing import Any


class DirectClient:
    """A PyBullet DIRECT client of its own (``cid``), disconnected by :meth:`close` or on leaving a ``with``."""

    def __init__(self) -> None:
        import pybullet as pb

        self._pb = pb
        self.cid: int | None = pb.connect(pb.DIRECT)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.cid is not None and self._pb.isConnected(self.cid):
            self._pb.disconnect(self.cid)
        self.cid = None

    def reset_simulation(self, gravity, time_step: float, solver_iterations: int, **engine: Any) -> None:
        """Empty the world and set gravity (m/s^2), the step (s), the solver iterations and any other
        engine parameters (``deterministicOverlappingPairs=1``, ...)."""
        pb, cid = self._pb, self.cid
        pb.resetSimulation(physicsClientId=cid)
        pb.setGravity(*gravity, physicsClientId=cid)
        pb.setTimeStep(time_step, physicsClientId=cid)
        pb.setPhysicsEngineParameter(numSolverIterations=solver_iterations, **engine, physicsClientId=cid)
