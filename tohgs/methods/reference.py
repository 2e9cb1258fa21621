"""Kind ``reference``: the ``Dataset`` row, held-out ground-truth task grasps of each test configuration.

Per test configuration with at least one ground-truth grasp, S of them are drawn without replacement (the
job's seeded numpy stream); a configuration with fewer grasps repeats them in turn (its DS is then a lower
bound). Configurations without a ground-truth grasp are left out. Evaluated exactly like a method's
grasps, the row checks the metrics and bounds what a method can reach.
"""

from __future__ import annotations

import numpy as np

from tohgs.methods.base import Method, Prediction, gt_rows


class Reference(Method):
    """Ground-truth task grasps as predictions (no components)."""

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        ids = gt_rows(shard, row)
        if len(ids) == 0:
            return None
        pick = rng.permutation(ids)[np.arange(self.settings.samples) % len(ids)]
        return Prediction(shard.contact[pick], shard.grasp[pick].astype(np.float64))


METHOD = Reference
