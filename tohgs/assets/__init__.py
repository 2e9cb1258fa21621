"""Assets: objects (pybullet_data, generated bricks, user meshes), the table and shelves.

Mesh validation and repair, rescaling to a graspable size, mass properties and convex decomposition.
"""
