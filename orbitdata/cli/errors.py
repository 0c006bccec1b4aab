"""One-line errors for the CLI: the library raises, only the CLI exits."""

from __future__ import annotations

import contextlib
import functools
import sys

import typer

# Errors that mean "the user asked for something impossible": print one line, exit 1.
USER_ERRORS = (ValueError, FileNotFoundError, FileExistsError, PermissionError, NotADirectoryError, RuntimeError)


def fail(message: str, code: int = 1) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code)


def usage(message: str) -> None:
    """Bad flag values: exit 2 like every other usage error."""
    fail(message, code=2)


@contextlib.contextmanager
def usage_errors(*errors: type[Exception]):
    """Inside: a library's verdict on flag values (a config's ValueError by default) is a usage error."""
    try:
        yield
    except errors or (ValueError,) as exc:
        usage(str(exc))


def friendly(func):
    """Turn library exceptions into a one-line message and a non-zero exit, no traceback."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except typer.Exit:
            raise
        except KeyboardInterrupt:
            typer.secho("interrupted; run the same command again to resume", err=True)
            sys.exit(130)
        except USER_ERRORS as exc:
            fail(str(exc))
        except OSError as exc:
            fail(f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": "))

    return wrapper
