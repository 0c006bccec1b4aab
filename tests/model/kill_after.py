"""Run the orbitmodel CLI and SIGKILL it right after the checkpoint of a given step: a crash the
tests resume from. ``python tests/model/kill_after.py STEP orbitmodel-args...`` (a test helper;
the library has no such hook)."""

import os
import signal
import sys

from orbitmodel.runs import RunDir


def main() -> None:
    step, args = int(sys.argv[1]), sys.argv[2:]
    save = RunDir.save_checkpoint

    def save_then_die(self, at: int, *rest, **kwargs):
        save(self, at, *rest, **kwargs)
        if at >= step:
            os.kill(os.getpid(), signal.SIGKILL)

    RunDir.save_checkpoint = save_then_die
    from orbitmodel.cli.app import app

    app(args=args, prog_name="orbitmodel")


if __name__ == "__main__":
    main()
