"""The quality verdict of a grasp, a leaf: PV and SD under the quality-ratio thresholds (QR's definition;
the tables, their intervals, the claims and ``tohgs grasp`` all take it from here)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

T = TypeVar("T")  # a numpy array or a pandas Series


@dataclass(frozen=True)
class QualityThresholds:
    """A grasp is of quality if PV < ``max_pv`` (m^3) and SD < ``max_sd`` (m); the paper's 3 cm^3, 2 cm."""

    max_pv: float = 3e-6
    max_sd: float = 0.02

    def passes(self, pv: T, sd: T) -> T:
        """The verdict per grasp: PV (m^3) under ``max_pv`` and SD (m) under ``max_sd``; arrays or pandas Series
        of the same shape in, booleans of it out (a NaN SD fails)."""
        return (pv < self.max_pv) & (sd < self.max_sd)


