"""Snakemake script of rule maps_figure: object clouds coloured by D_init, D_goal and contact, with the hand."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets  # noqa: E402
from tohgs.viz.maps import plot_maps  # noqa: E402

plot_maps(snakemake.input.shards, HandAssets.load(snakemake.input.hand), snakemake.output[0])
