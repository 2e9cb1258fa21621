"""Simulation: PyBullet worlds, the task scenes (Placing, Stacking, Shelving), crash isolation."""
