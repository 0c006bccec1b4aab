"""Evaluation: measurements of a trained run, each with the baselines beside it."""
