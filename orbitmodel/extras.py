"""Optional dependencies, imported on use: one error type with the install hint, which the CLI
prints as one line (``orbitmodel.cli.errors``)."""

from __future__ import annotations

VIZ = "pip install 'orbitdata[viz]'"


class MissingExtra(ImportError):
    """An optional dependency that a command needs is not installed; the message says how to add it."""


def pyplot():
    """``matplotlib.pyplot`` on the Agg canvas (no display), or :class:`MissingExtra`."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingExtra(f"figures need matplotlib, which is not installed: {VIZ} (or install matplotlib)") from None
    return plt
