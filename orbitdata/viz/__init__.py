"""Pictures of episodes: top-down maps (OpenCV, always available) and plots (matplotlib extra)."""
