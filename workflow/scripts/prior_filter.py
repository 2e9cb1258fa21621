"""Snakemake script of rule prior_filter: pass flags of one object's prior grasps (numpy only, no torch)."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.grasps.filter import filter_prior_grasps  # noqa: E402

filter_prior_grasps(snakemake.input.raw, snakemake.params.thresholds, snakemake.output[0])
