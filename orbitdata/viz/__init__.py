"""Pictures of episodes: top-down maps (OpenCV, always available), plots and videos (the ``viz`` extra)."""

from __future__ import annotations

from pathlib import Path


def overview_figure(out: Path, episodes, config) -> str | None:
    """Draw meta/overview.png for the card (a :data:`orbitdata.write.finalize.Figure`).

    Returns its path relative to ``out``, or None when matplotlib (``orbitdata[viz]``) is missing.
    """
    try:
        import matplotlib  # noqa: F401  (only the optional dependency may be missing)
    except ImportError:
        return None
    from orbitdata import schema as S
    from orbitdata.viz.overview import write_overview

    write_overview(out, episodes, config.sim.camera.far)
    return S.OVERVIEW_PATH
