"""One control step of several planning pilots at once: the lockstep flights' heavy calls.

Each episode keeps its own pilot (a :meth:`PlannerPilot.fork` of one: its MPPI nominal, point
memory, latent history and random generator), and :func:`plan_batch` serves all of them with
one call per model: the encoder on their N frames, the depth head on those that replan, and per
MPPI round one imagined rollout of their N x K candidates (world model and probe, the probe
alone when it reads no latent, or the rigid-body model). The obstacle points and the cost stay
per episode (each its own cloud, goal and clock). ``PlannerPilot.act`` is a batch of one, so an
episode flown alone and one flown in a batch differ only in the float reduction order of the
batched calls.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from orbitmodel.plan.cost import trajectory_cost
from orbitmodel.plan.dynamics import joined
from orbitmodel.plan.frames import PredictedDepth, encode_frames


@torch.inference_mode()
def plan_batch(pilots: list, observations: list[dict]) -> list[np.ndarray]:
    """(8,) thrusts in [0, 1] for each of ``pilots`` (forks of one planning pilot, each flying its
    own episode) from its observation: fold the frame in, replan (every ``replan_every`` steps),
    execute the first step of the plan."""
    start = time.perf_counter()
    lead = pilots[0]
    assert all(p.dynamics.__class__ is lead.dynamics.__class__ and p.depth is lead.depth for p in pilots), (
        "a batch holds forks of one pilot"
    )
    due = [i for i, p in enumerate(pilots) if p._step % p.config.replan_every == 0]
    patches = None  # (N, P, width): the frames' patch tokens, when the world model encoded them
    if lead.dynamics.needs_images:
        model = lead.dynamics.model
        with lead.dynamics.timings("encode"):
            cls, tokens = encode_frames(model, [o["image"] for o in observations])  # (N, width), (N, P, width)
            states = [torch.as_tensor(o["state"], dtype=torch.float32)[None] for o in observations]
            z = latents(model, cls, states)  # (N, D)
        for p, z_i, o in zip(pilots, z, observations):
            p.dynamics.push(z_i, p._previous, o)
        if isinstance(lead.depth, PredictedDepth) and lead.depth.model is model:
            patches = tokens
    else:
        for p, o in zip(pilots, observations):
            p.dynamics.observe(o, p._previous)
    if due:
        replan_batch([pilots[i] for i in due], [observations[i] for i in due], _rows(patches, due, len(pilots)))
    actions = [p._execute() for p in pilots]
    seconds = time.perf_counter() - start
    for p in pilots:
        p.step_seconds.append(seconds)
    return actions


def latents(model, cls: torch.Tensor, states: list[torch.Tensor]) -> torch.Tensor:
    """The N frames' latents (N, D) from their CLS features (N, width) and states N x (1, 16), one
    frame at a time: a product of one row takes another kernel than one of several, whose sums
    differ in the last bit, and a frame encoded alone (``LearnedDynamics.observe``) must get the
    same latent in a batch. The encoder and every candidates' call have many rows either way."""
    return joined([model.latent_from_cls(cls[i : i + 1], s) for i, s in enumerate(states)])


def _rows(x: torch.Tensor | None, rows: list[int], n: int) -> torch.Tensor | None:
    """``x[rows]``, or ``x`` itself when the rows are all of its n."""
    return x if x is None or len(rows) == n else x[rows]


def depth_maps(pilots: list, observations: list[dict], patches: torch.Tensor | None) -> list | None:
    """Each pilot's (16, 16) depth map of its frame (None for the oracles of the true obstacles):
    the depth head on the N frames' patch tokens at once (encoded here unless ``patches`` has them),
    or the rendered depth."""
    depth = pilots[0].depth
    if depth is None:
        return None
    if not isinstance(depth, PredictedDepth):
        return [depth(o) for o in observations]
    if patches is None:  # no world-model dynamics read the frames: the depth head is their only reader
        with depth.timings("depth-head"):
            _, patches = encode_frames(depth.model, [o["image"] for o in observations])
    return list(depth.maps(patches))  # N x (16, 16) metres


def replan_batch(pilots: list, observations: list[dict], patches: torch.Tensor | None = None) -> None:
    """Replan each pilot's MPPI nominal from its observation; every round's candidates of all the
    pilots are imagined by one ``rollout_many`` call, each pilot's drawn from its own generator."""
    start = time.perf_counter()
    lead = pilots[0]
    maps = depth_maps(pilots, observations, patches)
    fields = [p._obstacles(o, None if maps is None else maps[i]) for i, (p, o) in enumerate(zip(pilots, observations))]
    state0 = [torch.as_tensor(o["state"], dtype=torch.float32) for o in observations]  # N x (16,)
    dynamics = [p.dynamics for p in pilots]
    results, imagined = [None] * len(pilots), [None] * len(pilots)
    for _ in range(lead.config.mppi.iterations):
        candidates = [p.mppi.propose(p.generator) for p in pilots]  # N x (K, H, 8)
        imagined = type(lead.dynamics).rollout_many(dynamics, state0, candidates)  # N x (K, H, 16)
        with lead.timings("cost"):
            costs = [
                trajectory_cost(s, a, p.goal, p.goal_radius, p.round_field(f, s), p.config.cost, p.plan_times())[0]
                for p, s, a, f in zip(pilots, imagined, candidates, fields)
            ]  # N x (K,)
        results = [p.mppi.update(a, c) for p, a, c in zip(pilots, candidates, costs)]
    seconds = time.perf_counter() - start
    for p, result, field, states in zip(pilots, results, fields, imagined):
        p._planned(result, field, states, seconds)
