"""The version of orbitdata (the codebase that wrote a dataset records it in ``meta/info.json``)."""

__version__ = "0.1.0"
