"""Measurements of a trained run: closed-loop flight on the ``orbitdata fly`` grid, Figure 6."""
