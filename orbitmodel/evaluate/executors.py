"""Where a grid's chunks fly: one after another in this process, or as Ray tasks (``orbitdata[ray]``).

The pattern of ``orbitdata generate --executor ray``: a task per unit of work, results back to
the driver as they finish, in any order (the driver puts them in grid order). The cluster is the
address given (``ClosedLoopRequest.ray_address``), else the one ``RAY_ADDRESS`` names, else a
local Ray instance started on this machine's cores; a Ray instance already started in this
process (``ray.init``) is used as it is.
"""

from __future__ import annotations

from typing import Callable, Iterator

from orbitmodel.extras import MissingExtra

EXECUTORS = ("local", "ray")
RAY_HINT = "the Ray executor needs ray, which is not installed: pip install 'orbitdata[ray]'"


def run_local(task: Callable, calls: list[tuple]) -> Iterator:
    """``task(*call)`` for every call, here, in order."""
    for call in calls:
        yield task(*call)


def run_ray(task: Callable, calls: list[tuple], cpus: int = 1, address: str | None = None) -> Iterator:
    """``task(*call)`` for every call as a Ray task of ``cpus`` cores; results as they finish.
    ``address``: the cluster to join (None: ``RAY_ADDRESS``'s, else a local instance)."""
    try:
        import ray
    except ImportError:
        raise MissingExtra(RAY_HINT) from None
    started_here = not ray.is_initialized()
    if started_here:
        from orbitdata.write.executors import check_ray_address

        check_ray_address(address)
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=cpus)(task)
        pending = [remote.remote(*call) for call in calls]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()
