"""``expert-snapshot``: the static expert on a moving scene, a named weak pilot of the dynamic tier.

It plans once, at reset, with RRT* around the debris as it stands at t = 0 (a dynamic scenario's
obstacles are their poses at t = 0) and then tracks that path with the nominal body's PD, blind
to the drift, the tumble, the body as drawn and the fault: what a planner that assumes a frozen
scene would do.
"""

from __future__ import annotations

from orbitdata.fly.pilots.expert import ExpertPilot


class SnapshotExpertPilot(ExpertPilot):
    """:class:`ExpertPilot` under its own name (its RRT* plan is made on ``scenario.obstacles``, the t = 0 poses)."""

    name = "expert-snapshot"
