"""Training: the run folder (checkpoints, metrics), one loop shared by every stage, and the stages."""
