"""Evaluation: measurements of a trained run, each with the baselines beside it: latent rollouts
(Fig. 3, 4), closed-loop flight on the ``orbitdata fly`` grid (Fig. 6)."""
