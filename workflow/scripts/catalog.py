"""Snakemake script of checkpoint catalog: gather the objects' metadata and split by object."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.assets.objects import write_catalog  # noqa: E402

write_catalog(snakemake.input.objects, snakemake.params.split, snakemake.params.seed, snakemake.output[0],
              task_sets=snakemake.params.task_sets, skipped=snakemake.params.skipped,
              dir_split=snakemake.params.dir_split)
