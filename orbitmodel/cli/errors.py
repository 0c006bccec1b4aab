"""One-line errors: the library raises, only the CLI exits (2 for bad input, as for usage; 1 for a
missing optional dependency, a failing disk, or a grid's flight that fails once under way)."""

from __future__ import annotations

import functools
import inspect
import math
import sys

import typer

from orbitdata.load.source import HubUnavailable

BAD_INPUT = (ValueError, FileNotFoundError, FileExistsError, NotADirectoryError, PermissionError)


def first_line(exc: BaseException) -> str:
    """An exception's message in one line: its first, or its type's name when it has none."""
    return (str(exc).splitlines() or [type(exc).__name__])[0]


def positive(value: float | None) -> float | None:
    """A flag's callback: a finite number above 0 (None, the flag not given, passes)."""
    if value is not None and not 0 < value < math.inf:
        raise typer.BadParameter(f"{value:g} must be a finite number above 0")
    return value


def fail(message: str, code: int = 2) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code)


def friendly(func):
    """Library exceptions become one line on stderr and exit 2, never a traceback."""
    again = (
        "run the same command with --resume to continue"
        if "resume" in inspect.signature(func).parameters
        else "run the same command again"
    )

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except typer.Exit:
            raise
        except KeyboardInterrupt:
            typer.secho(f"interrupted; {again}", err=True)
            sys.exit(130)
        except ImportError as exc:  # MissingExtra, or an optional package's ImportError with its install hint
            if "pip install" not in str(exc):
                raise  # a real import bug keeps its traceback
            fail(first_line(exc), code=1)
        except BAD_INPUT as exc:
            fail(first_line(exc))
        except HubUnavailable as exc:  # a dataset given as a Hub repo id (or a mistyped path) the Hub did not give
            fail(first_line(exc), code=1)
        except OSError as exc:
            fail(f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), code=1)

    return wrapper
