"""Snakemake script of rule evaluate: one row of metrics per predicted grasp of a task and method."""
import logging
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets  # noqa: E402
from tohgs.io import atomic_path  # noqa: E402
from tohgs.metrics.evaluate import evaluate_predictions  # noqa: E402

inp, p = snakemake.input, snakemake.params
rows = evaluate_predictions(inp.predictions, inp.scenes, snakemake.params.objects_dir, f"{inp.supports}/supports.json",
                            HandAssets.load(inp.hand), p.sd, p.voxel_pitch, p.cache_dir, progress=True,
                            robust_sd=p.robust_sd, palm_sd=p.palm_sd, pv_mesh=p.pv_mesh, threads=snakemake.threads,
                            sd_hand=p.sd_hand)
with atomic_path(snakemake.output[0]) as tmp:
    rows.to_parquet(tmp, index=False)
logging.getLogger("evaluate").info("%d grasps of %d configurations -> %s", len(rows),
                                   rows.groupby(["object", "config_index"]).ngroups, snakemake.output[0])
