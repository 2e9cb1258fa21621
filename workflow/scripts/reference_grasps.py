"""Snakemake script of rule reference_grasps: the dataset row's held-out ground-truth grasps as predictions."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.data.predictions import reference_predictions  # noqa: E402

p = snakemake.params
reference_predictions(snakemake.input.shards, snakemake.wildcards.task, p.samples, p.seed, snakemake.output[0])
