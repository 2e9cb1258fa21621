"""The official TOHGS dataset (Liu, Chao, Chen, ICCV 2025): an importer into tohgs's stores and an exporter of
tohgs's predictions into the official evaluation's output format. ``docs/official_dataset.md`` is the guide.

- :mod:`tohgs.official.format`: the official tree's layout and constants, its names and paths, reading its
  files safely (:func:`~tohgs.official.format.load_official_npy`), parsing its rows, and the two worlds'
  frames (:func:`~tohgs.official.format.from_official_pose`, :func:`~tohgs.official.format.to_official_pose`).
- :mod:`tohgs.official.importer`: :func:`~tohgs.official.importer.import_official` (official tree -> tohgs's
  stores) and :func:`~tohgs.official.importer.read_import` (what a workflow needs of an import).
- :mod:`tohgs.official.exporter`: :func:`~tohgs.official.exporter.export_official` (a prediction store ->
  the official evaluation's ``<run>/<obj>.npy``).
- ``python -m tohgs.official import ROOT OUT`` / ``export PREDICTIONS SCENES_DIR RUN_DIR``: the command line
  (:mod:`tohgs.official.__main__`).
"""
