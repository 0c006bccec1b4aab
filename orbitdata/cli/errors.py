"""One-line errors for the CLI: the library raises, only the CLI exits.

Exit codes: 2 for a usage error (a bad flag value, an unknown option, a path that is not what
the command takes), 1 for a failure at run time (the Hub cannot be reached, a disk error),
130 when interrupted. :func:`run_app` runs a typer app so that its parse errors follow the same
rule: one line naming the flag, exit 2.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import signal
import sys
import threading

import typer

try:  # recent typer carries its own copy of click (typer._click), whose exceptions it raises
    from typer._click import exceptions as click_errors
except ImportError:  # pragma: no cover - older typer runs on click itself
    from click import exceptions as click_errors

# Errors that mean "the user asked for something impossible": print one line, exit 1.
USER_ERRORS = (ValueError, FileNotFoundError, FileExistsError, PermissionError, NotADirectoryError, RuntimeError)


def fail(message: str, code: int = 1) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code)


def usage(message: str) -> None:
    """Bad flag values: exit 2 like every other usage error."""
    fail(message, code=2)


@contextlib.contextmanager
def usage_errors(*errors: type[Exception], flags: dict[str, str] | None = None):
    """Inside: a library's verdict on flag values (a config's ValueError by default) is a usage error.
    ``flags`` maps a config field to the flag that set it (``{"image_size": "--image-size"}``): a
    verdict on that field then names the flag."""
    try:
        yield
    except errors or (ValueError,) as exc:
        message = str(exc)
        field = next((f for f in flags or {} if message.startswith(f"{f} ")), None)
        usage(f"{flags[field]}: {message}" if field else message)


def friendly(func=None, *, resumes: bool = False):
    """Turn library exceptions into a one-line message and a non-zero exit, no traceback.
    ``@friendly(resumes=True)``: a command that, run again after an interrupt, picks up its work."""
    if func is None:
        return functools.partial(friendly, resumes=resumes)
    again = "run the same command again" + (" to resume" if resumes else "")

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except typer.Exit:
            raise
        except KeyboardInterrupt:
            typer.secho(f"interrupted; {again}", err=True)
            sys.exit(130)
        except USER_ERRORS as exc:
            fail(str(exc))
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                where = f" while writing {exc.filename}" if exc.filename else ""
                fail(f"{exc.strerror}{where}: free some space there, then {again}")
            fail(f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": "))

    return wrapper


def _flag(param) -> str:
    """How the user wrote ``param``: its long option (``--episodes``), or an argument's name (``OUT``)."""
    opts = [o for o in getattr(param, "opts", []) if o.startswith("-")]
    if opts:
        return max(opts, key=len)
    return (getattr(param, "name", None) or "argument").upper()


def usage_line(exc: Exception) -> str:
    """One line for a parse error: the flag, the value given and what it must be, without
    pydantic's wording (``Input should be ...``) or click's box."""
    param = getattr(exc, "param", None)
    cause = exc.__cause__
    if isinstance(exc, click_errors.MissingParameter):
        message = exc.format_message()
    elif isinstance(exc, click_errors.BadParameter) and param is not None and hasattr(cause, "errors"):
        first = cause.errors()[0]  # a pydantic ValidationError: typer checks min/max and choices with it
        error = (first.get("ctx") or {}).get("error")
        why = str(error) if error is not None else first["msg"].replace("Input should be", "must be", 1)
        message = f"{_flag(param)} {first.get('input')}: {why}"
    elif isinstance(exc, click_errors.BadParameter) and param is not None:
        message = f"{_flag(param)}: {exc.message}"
    else:
        message = exc.format_message()
    ctx = getattr(exc, "ctx", None)
    hint = f" (see `{ctx.command_path} --help`)" if ctx is not None else ""
    return " ".join(f"{message.strip().rstrip('.')}{hint}".split())


def run_app(app: typer.Typer, args: list[str] | None = None) -> None:
    """Run a typer app as a program (``args``: the command line, default ``sys.argv[1:]``) and exit.

    A usage error (a bad or missing flag value, an unknown option or command) prints one line,
    ``error: <flag> ...``, and exits 2; ``--help`` prints the help; a command's ``typer.Exit``
    code is the exit code.
    """
    main = threading.current_thread() is threading.main_thread()
    before = signal.signal(signal.SIGTERM, _interrupt) if main else None  # `kill` stops it as Ctrl-C does
    command = typer.main.get_command(app)
    name = app.info.name if isinstance(app.info.name, str) else None  # None: from sys.argv, as click does
    try:
        code = command.main(args=args, prog_name=name, standalone_mode=False)
    except getattr(click_errors, "NoArgsIsHelpError", ()) as exc:  # the bare command: its help
        typer.echo(exc.format_message())
        sys.exit(exc.exit_code)
    except click_errors.UsageError as exc:
        _exit(usage_line(exc), 2)
    except click_errors.ClickException as exc:
        _exit(" ".join(exc.format_message().split()), exc.exit_code)
    except typer.Abort:
        _exit("aborted", 1)
    finally:
        if main:
            signal.signal(signal.SIGTERM, before)
    sys.exit(code if type(code) is int else 0)


def run_script(main) -> None:
    """Run a benchmark's or script's argparse ``main()`` as a program: bad input (a missing folder, a
    run or value it cannot take) prints one line, ``error: ...``, and exits 2, as the CLI does; its
    own return value is the exit code."""
    try:
        code = main()
    except KeyboardInterrupt:
        _exit("interrupted", 130)
    except USER_ERRORS as exc:
        _exit(str(exc).splitlines()[0] if str(exc) else type(exc).__name__, 2)
    sys.exit(code if type(code) is int else 0)


def child_reason(stderr: str, returncode: int) -> str:
    """Why a failed child command stopped, for a script's own one-line error: the last line it
    printed on stderr without its own ``error: `` prefix, else its exit code."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    return lines[-1].removeprefix("error: ") if lines else f"exit {returncode}"


def script_help(doc: str) -> str:
    """A script's --help description: its docstring's first paragraph, on one line."""
    return " ".join(doc.strip().split("\n\n")[0].split())


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _exit(message: str, code: int) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    sys.exit(code)
