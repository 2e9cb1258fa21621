"""Snakemake script of rule evaluate: one row of metrics per predicted grasp of a task and method."""
import logging
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

import torch  # noqa: E402

from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.io import atomic_path  # noqa: E402
from tohgs.metrics.evaluate import evaluate_predictions  # noqa: E402

torch.set_num_threads(snakemake.threads)
inp, p = snakemake.input, snakemake.params
rows = evaluate_predictions(inp.predictions, inp.scenes, Path(inp.supports).parent, f"{inp.supports}/supports.json",
                            HandModel(HandAssets.load(inp.hand)), p.sd, p.voxel_pitch, progress=True)
with atomic_path(snakemake.output[0]) as tmp:
    rows.to_parquet(tmp, index=False)
logging.getLogger("evaluate").info("%d grasps of %d configurations -> %s", len(rows),
                                   rows.groupby(["object", "config_index"]).ngroups, snakemake.output[0])
