"""Kind ``reference``: the ``Dataset`` row, held-out ground-truth task grasps of each test configuration.

Per test configuration, S of its ground-truth grasps in a seeded random order
(:func:`tohgs.methods.base.ground_truth_pick`: the same grasps the ground-truth-contact rows read, so the rows
are paired); a configuration with fewer grasps repeats them in turn (its DS is then a lower bound). The test
split holds only configurations with ground truth (:func:`tohgs.data.build_maps.with_ground_truth`); one
without would be left out, and the tables count it as missing. Evaluated exactly like a method's grasps,
the row checks the metrics and bounds what a method can reach.
"""

from __future__ import annotations

import numpy as np

from tohgs.methods.base import Method, Prediction


class Reference(Method):
    """Ground-truth task grasps as predictions (no components)."""

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        pick = self.ground_truth(shard, row)
        if len(pick) == 0:
            return None
        return Prediction(shard.contact[pick], shard.grasp[pick].astype(np.float64))


METHOD = Reference
