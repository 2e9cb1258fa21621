"""tohgs: task-oriented human grasp synthesis (Liu, Chao, Chen, ICCV 2025), reproducible and open."""

__version__ = "0.1.0"
