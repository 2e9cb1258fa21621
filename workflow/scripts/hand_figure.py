"""Snakemake script of rule hand_figure: rest pose, presets, part labels and contact candidates."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.viz.hand import plot_hand  # noqa: E402

plot_hand(HandModel(HandAssets.load(snakemake.input.hand)), snakemake.output[0])
