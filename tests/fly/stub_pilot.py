"""A stand-in for a learned pilot, living outside orbitdata (as orbitmodel's planner will).

It needs the camera, is not privileged, and logs what it is given (``log=PATH``), so tests can
check that it sees images and never the obstacle list. Registered by the tests, in process with
``register_pilot`` and through an ``orbitdata.pilots`` entry point in a subprocess.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from orbitdata.fly import Pilot, Task
from orbitdata.scenario.spec import Lighting, Obstacle, Scenario

GROUND_TRUTH = (Scenario, Obstacle, Lighting)


def ground_truth_in(value, path: str = "") -> list[str]:
    """Where in ``value`` (dicts, sequences, dataclasses) a scenario, obstacle or lighting hides."""
    if isinstance(value, GROUND_TRUTH):
        return [path or type(value).__name__]
    if dataclasses.is_dataclass(value):
        value = dataclasses.asdict(value)
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in ground_truth_in(v, f"{path}.{k}")]
    if isinstance(value, (list, tuple)):
        return [p for i, v in enumerate(value) for p in ground_truth_in(v, f"{path}[{i}]")]
    return []


class SeeingPilot(Pilot):
    name = "stub"
    needs_images = True

    def __init__(self, log: str | None = None):
        self.log = log
        self.episodes: list[dict] = []

    def reset(self, task: Task) -> None:  # not privileged: there is no scenario argument to fill
        self.episodes.append(
            {
                "task": dataclasses.asdict(task),
                "ground_truth": ground_truth_in(task),
                "steps": 0,
                "keys": [],
                "image": [],
                "depth": [],
                "depth_low": [],
                "mean_rgb": [],
            }
        )
        self.goal = np.asarray(task.goal, dtype=np.float64)

    def act(self, obs: dict) -> np.ndarray:
        ep = self.episodes[-1]
        ep["steps"] += 1
        ep["ground_truth"] += ground_truth_in(obs)
        ep["keys"] = sorted(set(ep["keys"]) | set(obs))
        for key in ("image", "depth", "depth_low"):
            if key in obs:
                seen = [*obs[key].shape, str(obs[key].dtype)]
                if seen not in ep[key]:
                    ep[key].append(seen)
        ep["mean_rgb"].append(float(obs["image"].mean()))  # a learned pilot would encode this
        if self.log:
            with open(self.log, "w") as f:
                json.dump(self.episodes, f)
        return np.zeros(8)  # drift: a stub need not fly well


def make_stub(config, log: str | None = None) -> SeeingPilot:
    """The factory orbitdata calls: ``factory(config, **options)``."""
    return SeeingPilot(log)
