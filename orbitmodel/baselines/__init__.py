"""Baselines trained on the same data and flown on the same grid as the learned planner."""
