"""Snakemake script of the official rules: copy one piece of an official import into results/."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

import logging  # noqa: E402

from tohgs.io import copy_atomic  # noqa: E402

copy_atomic(snakemake.input[0], snakemake.output[0])
logging.getLogger("official_copy").info("copied %s -> %s", snakemake.input[0], snakemake.output[0])
