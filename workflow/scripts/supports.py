"""Snakemake script of rule supports: the table and the parametric shelves."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.assets.supports import write_supports  # noqa: E402

write_supports(snakemake.params.table, snakemake.params.shelves, snakemake.output[0])
