"""Repeatable ``KEY=VALUE`` flags (``orbitdata fly --pilot-option``, ``orbitmodel eval closed-loop --set``)."""

from __future__ import annotations

from orbitdata.cli.errors import usage


def key_values(pairs: list[str], flag: str, example: str) -> dict[str, str]:
    """``["a=1", "b=x"]`` -> ``{"a": "1", "b": "x"}``; a pair without ``=`` or a key is a usage
    error naming ``flag`` and an ``example`` pair. The values stay strings: the receiver converts
    and checks them."""
    options = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            usage(f"{flag} {pair!r} must be KEY=VALUE, e.g. {flag} {example}")
        options[key.strip()] = value
    return options
