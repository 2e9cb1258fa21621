"""Snakemake script of rule prior_filter: pass flags of one object's prior grasps."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.grasps.prior import filter_prior_grasps  # noqa: E402
from tohgs.hand import HandAssets  # noqa: E402

filter_prior_grasps(snakemake.input.raw, HandAssets.load(snakemake.input.hand).joint_limits, snakemake.params.thresholds,
                    snakemake.output[0])
