"""Figures: meshes, scenes, grasps and maps rendered headless with matplotlib."""
