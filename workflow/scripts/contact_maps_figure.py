"""Snakemake script of rule contact_maps_figure: predicted contact maps next to the ground truth."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.viz.predictions import plot_contact_maps  # noqa: E402

plot_contact_maps(snakemake.input.predictions, snakemake.input.shards, snakemake.output[0], snakemake.params.configs,
                  labels=snakemake.params.labels)
