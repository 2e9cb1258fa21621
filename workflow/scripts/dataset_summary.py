"""Snakemake script of rule dataset_summary: task-grasp counts, scene difficulty, shard sizes and the paper-scale estimate."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.data.build_maps import summarize_dataset  # noqa: E402

inp, p = snakemake.input, snakemake.params
summarize_dataset(inp.task_grasps, inp.shards, snakemake.output[0], scene_stores=inp.scenes, objects_dir=p.objects_dir,
                  seed=p.seed)
