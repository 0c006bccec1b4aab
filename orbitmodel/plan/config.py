"""A planning pilot's settings, and the named planner presets that the CLI and the scripts fly.

``paper`` is the design's MPPI (K = 256 samples, H = 50 frames, the world model's own history of
latents); ``cpu`` is what the reported grids fly on a 2-core CPU with the ``cpu-step5`` world
model: K = 32, H = 50, a history of 2 latents (its latency: ``benchmarks/bench_plan.py
--planner cpu``). Without a name, a CUDA machine flies ``paper`` and a CPU ``cpu``
(:func:`default_planner_preset`). ``orbitmodel eval closed-loop --preset NAME --set KEY=VALUE``
(or ``--pilot-option``) changes single fields of the chosen preset; the result files record
the preset and every field (``probe`` only when it is not the run's own, ``obstacle_motion`` and
the tracker's knobs only when the obstacles are not taken to stand still: :func:`recorded`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

from orbitmodel.plan.cost import CostConfig
from orbitmodel.plan.depth_recipe import CHOICES, MAX_RANGE, is_head_name
from orbitmodel.plan.mppi import MPPIConfig
from orbitmodel.plan.tracker import TrackerConfig
from orbitmodel.probe.variants import FLOWN, LATENT, VARIANTS

PROBES = ("", LATENT, *VARIANTS)  # the probes a planner may read: "" is the run's own (RUN/probe)
# How the planner expects the obstacles to move over a plan's horizon: "static", "tracker" and
# "imagined" for the pilots that see them (depth), "true" and "frozen" for the oracles handed the scenario.
OBSTACLE_MOTIONS = ("static", "tracker", "imagined", "true", "frozen")
BODIES = ("true", "nominal", "fitted", "inferred", "corrected")  # the body a pilot plans a dynamic-tier episode with
HISTORY_BODIES = ("fitted", "inferred")  # the bodies a pilot infers from its own history (no record read)
PRECISIONS = ("float32", "bfloat16")  # what the world model's rollout runs in


@dataclass(frozen=True)
class PlannerConfig:
    """Everything a planning pilot is tuned by.

    Args:
        mppi: sampling (K, H, noise, temperature); see :class:`MPPIConfig`.
        cost: weights and margins; see :class:`CostConfig`.
        noise: "wrench" (perturb along thrust patterns that make independent body forces and
            torques, torques scaled by ``torque_noise``) or "thrust" (each thruster alone).
        torque_noise: scale of the torque patterns against the force patterns.
        history: latents the world model sees per imagined step (0: its own ``config.history``).
            Fewer is faster (the rollout's cost is proportional) and less accurate.
        memory_frames: depth frames whose points stay in the world-frame cloud (1: current only;
            50 = 2 s, chosen on a validation grid seed, ``docs/planner.md``).
        max_range: metres; depth cells farther than this are not obstacles to plan around.
        depth_head: which depth head gives the point cloud: "stage1" (trained with the world
            model), "refit" (``orbitmodel depth RUN``: refitted for near cells, in RUN/depth),
            "auto" (the refit when the run has one, else Stage I's), or NAME, a head refitted on
            another dataset's frames (``orbitmodel depth RUN DATASET --name NAME``, in RUN/depth-NAME).
        footprint: a point's sphere radius in half cell widths at its depth.
        support: keep a depth cell only if this many of its 8 neighbours are at a similar depth
            (``obstacles.supported_cells``; 0: keep every cell within ``max_range``; 1 chosen on
            a validation grid seed, ``docs/planner.md``).
        reach: metres of clearance beyond which points are ignored (>= the collision margin).
        rigid_substeps: substeps of the rigid-body model (the simulator's 8 = exact).
        replan_every: control steps between replans (in between, the plan's next step runs).
        compile: run the world model's imagined step through ``torch.compile``
            (:meth:`WorldModel.compile_rollout`; learned-dynamics pilots only). Same plans to
            float rounding, faster rollouts, slow first replans.
        precision: "float32", or "bfloat16": the world model's rollout (action encoder, predictor,
            projector) runs in bfloat16 (:meth:`WorldModel.bfloat16_rollout`; pilots that roll the
            world model out only). Fast on a CPU with AVX-512 BF16 or AMX, emulated and can be slower
            elsewhere; the encoder, the depth head, the probe and the cost stay float32.
        record: keep each replan's best imagined path and the believed points (for videos).
        image_codec: hand the pilot its camera through the dataset's JPEG codec (the reported
            grids fly raw renders).
        probe: which of the run's probes reads the imagined states: "" the run's own (``RUN/probe``,
            the flown one; ``thrust_probe`` names it too), a Table I variant (``RUN/probe-NAME``,
            ``orbitmodel probe RUN DATA --variant NAME``), or "latent_probe", the candidate chosen
            on the validation episodes (``RUN/latent_probe.json``). One that reads no latent
            (``thrust_only``) makes the planner skip the world model's rollout (``LearnedDynamics``).
        obstacle_motion: where each rollout step's clearance is taken. "static": the obstacles
            stand still (the point memory; an oracle's true obstacles, which must not move). "tracker":
            the depth points clustered into tracks, each carried along its fitted velocity to the
            step's time (``plan.tracker``). "imagined" (the learned planner only): each candidate
            meets the debris where the depth it imagines at that step puts them (``plan.imagined``;
            ``orbitmodel depth RUN DATA --imagined`` fits the head). Oracles only: "true", each obstacle where its exact
            motion puts it at the step's time; "frozen", where it is at the replan.
        tracker: the tracker's knobs (``obstacle_motion="tracker"`` only); see :class:`TrackerConfig`.
        body: the body the rigid-body oracles handed a dynamic-tier episode plan with: "true", the
            episode's (its mass, inertia, centre of mass and thruster fault, and the CW terms:
            ``plan.true_body``), or "nominal", the fault-free design body with the CW terms
            (``oracle-nominal``: what ignoring the fault costs). The static tier has one body.
            "fitted": the thrust response fitted to the pilot's own last ``fit_frames`` frames
            (``plan.fitted_body``). It reads no record, so the planner may fly it too: the world
            model then sees (depth head, imagined depth) and the fitted body gives the states.
            "inferred": the fit under a prior a network learned from the tier's training episodes
            (``plan.inferred_body``; ``orbitmodel body RUN DATASET`` trains it into RUN/body, whose
            ridge it flies with). It needs a run, so only pilots flown with one.
            "corrected" (the pilots planning with the world model: planner, oracle-learned-dyn): the
            world model's own dynamics, each frame's velocity and rate increments corrected by the
            thrust response of their misses over the last ``fit_frames`` frames (``plan.corrected_body``).
        fit_frames: frames of history the body is fitted to (``body="fitted"``, "corrected", or
            "inferred": at most the frames its prior was trained on).
        fit_ridge: how hard the fitted body is pulled towards the design's (``body="fitted"``), or the
            correction towards none (``body="corrected"``).
        fit_steps: ``body="corrected"``: the imagined steps fitted, each with a correction of its
            own (1: the first step's misses correct every step).
    """

    mppi: MPPIConfig = field(default_factory=MPPIConfig)
    cost: CostConfig = field(default_factory=CostConfig)
    noise: str = "wrench"
    torque_noise: float = 0.3
    history: int = 0
    memory_frames: int = 50
    max_range: float = MAX_RANGE
    depth_head: str = "auto"
    footprint: float = 1.0
    support: int = 1
    reach: float = 1.0
    rigid_substeps: int = 1
    replan_every: int = 1
    compile: bool = False
    precision: str = "float32"
    record: bool = False
    image_codec: bool = False
    probe: str = ""
    obstacle_motion: str = "static"
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    body: str = "true"
    fit_frames: int = 40
    fit_ridge: float = 1e-5
    fit_steps: int = 1

    def __post_init__(self):
        if self.noise not in ("wrench", "thrust"):
            raise ValueError(f"noise={self.noise!r}: use 'wrench' or 'thrust'")
        if self.depth_head not in CHOICES and not is_head_name(self.depth_head):
            raise ValueError(
                f"depth_head={self.depth_head!r}: use 'auto', 'stage1', 'refit' or the name of a head "
                "refitted with `orbitmodel depth RUN DATASET --name NAME`"
            )
        if self.history < 0:
            raise ValueError(f"history={self.history}: give 0 (the world model's own) or a positive number of latents")
        if not 0 <= self.support <= 8:
            raise ValueError(f"support={self.support}: give 0 (off) to 8 neighbours")
        if self.replan_every < 1 or self.memory_frames < 1:
            raise ValueError(f"replan_every={self.replan_every} and memory_frames={self.memory_frames} must be >= 1")
        if self.replan_every > self.mppi.horizon:
            raise ValueError(
                f"replan_every={self.replan_every}: a plan holds {self.mppi.horizon} frames (horizon); replan within them"
            )
        if not (self.max_range > 0 and self.footprint > 0 and self.torque_noise >= 0):
            raise ValueError(
                f"max_range={self.max_range}, footprint={self.footprint} and torque_noise={self.torque_noise}: give "
                "positive metres and cell widths and a torque scale >= 0"
            )
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision={self.precision!r}: use {' or '.join(PRECISIONS)}")
        if self.probe not in PROBES:
            raise ValueError(
                f"probe={self.probe!r}: give {LATENT} (the one chosen on validation) or a probe variant of the "
                f"run ({', '.join(VARIANTS)}); leave it out for the run's own ({FLOWN})"
            )
        if self.probe == FLOWN:  # the run's own probe, by its Table I name: one spelling in every record
            object.__setattr__(self, "probe", "")
        if self.obstacle_motion not in OBSTACLE_MOTIONS:
            raise ValueError(
                f"obstacle_motion={self.obstacle_motion!r}: use static, tracker or imagined (pilots that see the obstacles), "
                "true or frozen (oracles handed the scenario)"
            )
        if self.body not in BODIES:
            raise ValueError(
                f"body={self.body!r}: use true (the episode's body and fault), nominal (the design's), fitted "
                "(fitted to the pilot's own history), inferred (the fit under the prior RUN/body learned) or "
                "corrected (the world model's dynamics corrected by their misses over the pilot's history)"
            )
        if self.body == "inferred" and self.fit_ridge != PlannerConfig.fit_ridge:
            raise ValueError("fit_ridge: body=inferred flies the ridge its prior was trained with; drop fit_ridge")
        if self.fit_steps < 1:
            raise ValueError(f"fit_steps={self.fit_steps}: give at least 1 imagined step")
        if self.fit_steps != 1 and self.body != "corrected":
            raise ValueError(
                f"fit_steps={self.fit_steps} sets body=corrected's fit; add --set body=corrected or drop it"
            )
        if self.fit_frames < 1 or self.fit_ridge <= 0:
            raise ValueError(
                f"fit_frames={self.fit_frames} and fit_ridge={self.fit_ridge}: give at least 1 frame and a positive ridge"
            )
        if self.reach < self.cost.margin + self.cost.hull_radius:
            raise ValueError(
                f"reach={self.reach} m is shorter than the collision ramp "
                f"({self.cost.hull_radius + self.cost.margin:.2f} m)"
            )


def recorded(config: PlannerConfig) -> dict:
    """The settings a result file records: every field, with ``probe`` left out when it is the run's
    own (the default), ``precision`` when float32 (the default), ``obstacle_motion`` when "static"
    (the default), ``tracker`` when no tracker flies, ``body`` when "true" (the default) and the
    fit's knobs when nothing is fitted (an inferred body keeps ``fit_frames``; its ridge is the
    inference's; ``fit_steps`` is the corrected body's only), so that the flights of the defaults
    all record the same settings."""
    out = dataclasses.asdict(config)
    if not config.probe:
        del out["probe"]
    if config.precision == "float32":
        del out["precision"]
    if config.obstacle_motion == "static":
        del out["obstacle_motion"]
    if config.obstacle_motion != "tracker":
        del out["tracker"]
    if config.body == "true":
        del out["body"]
    if config.body != "corrected":
        del out["fit_steps"]
    if config.body not in ("fitted", "corrected"):
        del out["fit_ridge"]
        if config.body != "inferred":
            del out["fit_frames"]
    return out


PLANNER_PRESETS: dict[str, Callable[[], PlannerConfig]] = {
    "paper": lambda: PlannerConfig(),
    "cpu": lambda: PlannerConfig(mppi=MPPIConfig(samples=32, horizon=50), history=2),
}


def default_planner_preset() -> str:
    """The preset that suits this machine: ``paper`` (K 256) with CUDA, ``cpu`` (K 32) without."""
    import torch

    return "paper" if torch.cuda.is_available() else "cpu"


def planner_config(preset: str | None = None, **options) -> PlannerConfig:
    """The planner preset ``preset`` with single fields changed: ``options`` are MPPIConfig,
    CostConfig, TrackerConfig and PlannerConfig field names (values may be strings, as a command line gives them).
    ``preset`` None: :func:`default_planner_preset`."""
    preset = preset or default_planner_preset()
    if preset not in PLANNER_PRESETS:
        raise ValueError(f"unknown planner preset {preset!r}; choose one of {', '.join(PLANNER_PRESETS)}")
    base = PLANNER_PRESETS[preset]()
    parts: dict[type, dict] = {MPPIConfig: {}, CostConfig: {}, TrackerConfig: {}, PlannerConfig: {}}
    for key, value in options.items():
        owner = next((cls for cls in parts if key in {f.name for f in dataclasses.fields(cls)}), None)
        if owner is None or key in ("mppi", "cost", "tracker"):
            raise ValueError(
                f"unknown planner option {key!r}; use a field of MPPIConfig, CostConfig, TrackerConfig or PlannerConfig"
            )
        kind = type(getattr(owner(), key))
        if kind is bool and isinstance(value, str) and value.lower() not in ("1", "true", "yes", "0", "false", "no"):
            raise ValueError(f"planner option {key}={value!r}: give true or false")
        try:
            parts[owner][key] = (
                (value.lower() in ("1", "true", "yes")) if kind is bool and isinstance(value, str) else kind(value)
            )
        except ValueError:
            what = {int: "a whole number", float: "a number"}.get(kind, f"a {kind.__name__}")
            raise ValueError(f"planner option {key}={value!r}: give {what}") from None
        if kind is float and not math.isfinite(parts[owner][key]):
            raise ValueError(f"planner option {key}={value!r}: give a finite number")
    return dataclasses.replace(
        base,
        mppi=dataclasses.replace(base.mppi, **parts[MPPIConfig]),
        cost=dataclasses.replace(base.cost, **parts[CostConfig]),
        tracker=dataclasses.replace(base.tracker, **parts[TrackerConfig]),
        **parts[PlannerConfig],
    )
