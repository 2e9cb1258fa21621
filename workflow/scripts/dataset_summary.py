"""Snakemake script of rule dataset_summary: task-grasp counts, shard sizes and the paper-scale estimate."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.data.build_maps import summarize_dataset  # noqa: E402

summarize_dataset(snakemake.input.task_grasps, snakemake.input.shards, snakemake.output[0])
