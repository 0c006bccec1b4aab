"""Where work units run: a local process pool (default) or a Ray cluster (``orbitdata[ray]``).

Both yield ``UnitResult`` objects to the driver, which alone writes files; results may arrive
in any order, and the output does not depend on it.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import socket
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Iterator

from orbitdata.write.plan import Unit
from orbitdata.write.worker import UnitResult, run_unit_from_dict

RAY_HINT = "the Ray executor needs the 'ray' extra: pip install 'orbitdata[ray]'"


PR_SET_PDEATHSIG = 1  # prctl(2)


def check_ray_address(address: str | None, flag: str = "--ray-address", timeout: float = 5.0) -> None:
    """Refuse, in ``timeout`` seconds, a cluster address (``host:port`` or ``ray://host:port``) where
    nothing answers: ``ray.init`` would retry it for minutes. ``None`` checks ``RAY_ADDRESS``, the
    address Ray joins then; "auto", "local" and no address at all are Ray's to resolve."""
    if address is None:
        address, flag = os.environ.get("RAY_ADDRESS"), "RAY_ADDRESS"
    host, sep, port = (address or "").removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise ValueError(
            f"{flag} {address}: no Ray cluster answers there ({why}); start one with `ray start --head` "
            "and give the address it prints"
        ) from None


def die_with_parent(parent: int) -> None:
    """In a worker: end when ``parent``, the process that started it, ends, however it ends (Linux;
    a killed generate otherwise leaves its workers computing for nobody)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux
        return
    if os.getppid() != parent:  # the parent ended before the call took effect
        os._exit(1)


def run_local(config: dict, units: list[Unit], workers: int) -> Iterator[UnitResult]:
    """Run units in ``workers`` spawned processes (in-process when workers == 1)."""
    if workers <= 1:
        for unit in units:
            yield run_unit_from_dict(config, unit)
        return
    # spawn, not fork: a forked GL/EGL context is undefined behaviour.
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=die_with_parent, initargs=(os.getpid(),)
    ) as pool:
        pending = set()
        queue = list(units)
        # Keep a bounded number of units in flight so results stream back steadily.
        while queue or pending:
            while queue and len(pending) < 2 * workers:
                pending.add(pool.submit(run_unit_from_dict, config, queue.pop(0)))
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()


def run_ray(config: dict, units: list[Unit], address: str | None, workers: int) -> Iterator[UnitResult]:
    """Run units as Ray tasks; results (Parquet bytes) come back through the object store."""
    try:
        import ray
    except ImportError:
        raise RuntimeError(RAY_HINT) from None
    started_here = not ray.is_initialized()
    if started_here:
        check_ray_address(address or None)
        kwargs = {"address": address} if address else {"num_cpus": workers}
        on_term = signal.getsignal(signal.SIGTERM)
        ray.init(include_dashboard=False, log_to_driver=False, **kwargs)
        if on_term is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, on_term)  # ray.init sets its own; keep the command's (cli.errors)
    try:
        task = ray.remote(num_cpus=1)(run_unit_from_dict)
        pending = [task.remote(config, unit) for unit in units]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()
