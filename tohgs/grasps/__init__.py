"""Grasps: force-closure synthesis (prior grasps), the quality filter, task expansion."""
