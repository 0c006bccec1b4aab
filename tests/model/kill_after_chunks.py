"""Run the orbitmodel CLI with a grid's chunks one batch each and SIGKILL it right after its N-th
chunk is kept: a cut flight the tests continue. ``python tests/model/kill_after_chunks.py N
orbitmodel-args...`` (a test helper; the library has no such hook)."""

import os
import signal
import sys

from orbitmodel.evaluate import kept_chunks, lockstep


def main() -> None:
    after, args = int(sys.argv[1]), sys.argv[2:]
    lockstep.ROUNDS_PER_CHUNK = 1
    add, added = kept_chunks.ChunkLog.add, []

    def add_then_die(self, chunk) -> None:
        add(self, chunk)
        added.append(chunk)
        if len(added) >= after:
            os.kill(os.getpid(), signal.SIGKILL)

    kept_chunks.ChunkLog.add = add_then_die
    from orbitmodel.cli.app import app

    app(args=args, prog_name="orbitmodel")


if __name__ == "__main__":
    main()
