"""Snakemake script of rule prior_summary: accepted grasps and failures per check, per object."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.grasps.filter import summarize_prior_grasps  # noqa: E402

summarize_prior_grasps(snakemake.input.stores, snakemake.output[0])
