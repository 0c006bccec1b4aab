"""Make a planning pilot from a trained run: load what its variant needs, check it fits.

:func:`build_pilot` is the library entry; :func:`pilot_factory` adapts it to
``orbitdata.fly``'s registry (``factory(config, **options) -> Pilot``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from orbitdata.sim.config import SimConfig
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import HISTORY_BODIES, PlannerConfig, planner_config
from orbitmodel.plan.corrected_body import CorrectedLearnedDynamics
from orbitmodel.plan.depth_refit import head_source, refit_head_for
from orbitmodel.plan.dynamics import LearnedDynamics, RigidBodyDynamics
from orbitmodel.plan.fitted_body import FittedBodyDynamics, FittedBodyLearnedDynamics
from orbitmodel.plan.frames import FrameEncoder, PredictedDepth
from orbitmodel.plan.imagined_fit import load_imagined_depth
from orbitmodel.plan.inferred_body import InferredBodyDynamics, load_inference
from orbitmodel.plan.obstacles import Camera
from orbitmodel.plan.pilot import OraclePilot, PlannerPilot, Variant
from orbitmodel.plan.timing import Timings
from orbitmodel.probe import PhysicsProbe
from orbitmodel.probe.variants import FLOWN, LATENT
from orbitmodel.runs import RunError, resolve_run


def sensor_depth(obs: dict) -> np.ndarray:
    """The rendered depth_low: a perfect depth head (the ``oracle-true-dyn-sensor`` variant)."""
    return obs["depth_low"]


def load_world_model(run: str | Path | None, variant: Variant):
    """The run's world model in eval mode; raises a one-line error when the variant needs one and there is none."""
    if run is None:
        raise ValueError(f"pilot {variant.value} plans with the world model: give the run folder (RUN)")
    return WorldModel.from_pretrained(run)


def predicted_depth(run: Path, model, choice: str, timings: Timings, frames: FrameEncoder) -> PredictedDepth:
    """The depth head ``choice`` names (``PlannerConfig.depth_head``) on the shared frame encoder."""
    head = refit_head_for(run, model, choice)
    return PredictedDepth(model, timings, head, frames, head_source(choice, head))


def load_planner_probe(run: Path, world_model: str, name: str = "") -> PhysicsProbe:
    """The probe a planner reads (``PlannerConfig.probe``): "" the run's own (``RUN/probe``), a
    variant's (``RUN/probe-NAME``), or "latent_probe", the candidate chosen on the validation
    episodes (``RUN/latent_probe.json``); ``world_model``: the run's weights fingerprint, which the
    probe must have been trained on. RunError naming the command that makes a missing one."""
    if name == LATENT:
        from orbitmodel.probe.table1 import load_choice

        return load_choice(run, world_model)[1]
    return PhysicsProbe.from_pretrained(run, world_model=world_model, variant=name or FLOWN)


def camera_for_run(sim: SimConfig, model) -> SimConfig:
    """The simulator's camera set to the run's image size and field of view.

    The camera of ``sim`` must be the default one or already the run's: a checkpoint trained at
    another size or field of view would see different images (raises RunError).
    """
    size, fovy = model.config.image_size, float(model.run_info.fovy_deg)
    cam = sim.camera
    default = type(cam)()
    if (cam.image_size, cam.fovy_deg) not in ((size, fovy), (default.image_size, default.fovy_deg)):
        raise RunError(
            f"the run sees {size} px images at {fovy:g} deg, but the simulator's camera is "
            f"{cam.image_size} px at {cam.fovy_deg:g} deg; fly it with the run's camera (drop the "
            "camera settings from --config) or use a run trained on such images"
        )
    return dataclasses.replace(sim, camera=dataclasses.replace(cam, image_size=size, fovy_deg=fovy))


def build_pilot(
    variant: Variant | str,
    run: str | Path | None = None,
    config: PlannerConfig = PlannerConfig(),
    sim: SimConfig = SimConfig(),
    timings: Timings | None = None,
) -> tuple[PlannerPilot, SimConfig]:
    """The pilot of ``variant`` and the simulator settings it must fly in (the run's camera).
    ``run``: a run folder or a Hub model repo id (``owner/name[@revision]``, ``orbitmodel push``).

    Raises RunError (a ValueError) for a run without weights or the probe ``config.probe`` names,
    or with another camera.
    """
    if variant not in {v.value for v in Variant}:
        raise ValueError(f"pilot {variant!r}: give one of {', '.join(v.value for v in Variant)}")
    variant = Variant(variant)
    if not isinstance(config, PlannerConfig):
        raise ValueError(
            f"config is a {type(config).__name__}: give a PlannerConfig, such as planner_config({config!r})"
            if isinstance(config, str)
            else f"config is a {type(config).__name__}: give a PlannerConfig (planner_config(NAME))"
        )
    timings = timings or Timings()
    run = None if run is None else resolve_run(run)  # once: the probe and the depth head read the same folder
    model = load_world_model(run, variant) if variant.needs_model else None
    frames = None
    if model is not None:
        sim = camera_for_run(sim, model)
        frames = FrameEncoder(model)  # one ViT pass per frame for the dynamics and the depth head
    if variant.learned_dynamics:
        step = model.config.frame_step
        if config.mppi.horizon % step:
            raise RunError(
                f"{run} predicts {step} frames per step, so the plan's horizon must be a multiple of "
                f"{step} frames (got {config.mppi.horizon}); pass --horizon "
                f"{max(step, config.mppi.horizon // step * step)}"
            )
        prepare_rollout(model, config)
        probe = load_planner_probe(run, model.fingerprint, config.probe)
        if config.body in HISTORY_BODIES:  # the world model sees; the body inferred from history gives the states
            body = body_from_history(run, sim, config, timings)
            imagine = config.obstacle_motion == "imagined"
            dynamics = FittedBodyLearnedDynamics(
                model, probe, body, imagine, timings=timings, history=config.history or None, frames=frames
            )
        elif config.body == "corrected":  # the world model's dynamics, corrected by their misses over the history
            dynamics = CorrectedLearnedDynamics(
                model,
                probe,
                config.fit_frames,
                config.fit_ridge,
                config.fit_steps,
                timings=timings,
                history=config.history or None,
                frames=frames,
            )
        else:
            dynamics = LearnedDynamics(model, probe, timings, history=config.history or None, frames=frames)
    else:
        if config.probe:
            raise ValueError(
                f"probe={config.probe}: pilot {variant.value} plans with the rigid-body model, which reads no probe; "
                "drop the probe setting or fly a pilot that plans with the world model"
            )
        if config.precision != "float32":
            raise ValueError(
                f"precision={config.precision}: pilot {variant.value} plans with the rigid-body model, not the world "
                "model's rollout; drop the precision setting or fly a pilot that plans with the world model"
            )
        if config.body in HISTORY_BODIES:
            dynamics = body_from_history(run, sim, config, timings)
        else:
            dynamics = RigidBodyDynamics(sim, config.rigid_substeps, timings)
    depth = {
        "depth-head": lambda: predicted_depth(run, model, config.depth_head, timings, frames),
        "sensor": lambda: sensor_depth,
        "true": lambda: None,
    }[variant.obstacles]()
    camera = Camera.from_sim(sim)
    if config.obstacle_motion == "imagined":
        if not (variant.learned_dynamics and not variant.privileged and dynamics.reads_latent):
            raise ValueError(
                f"obstacle_motion=imagined: pilot {variant.value} with probe {config.probe or FLOWN} imagines no "
                "latents to read depth from; fly the planner with a probe that reads them"
            )
        imagined = load_imagined_depth(run, model, timings)
        return PlannerPilot(variant, dynamics, depth, camera, config, sim, timings, imagined), sim
    cls = OraclePilot if variant.privileged else PlannerPilot
    return cls(variant, dynamics, depth, camera, config, sim, timings), sim


def prepare_rollout(model, config: PlannerConfig) -> None:
    """Make the world model's rollout run as ``config`` flies it: in bfloat16 (``precision``), then
    through ``torch.compile`` (``compile``)."""
    if config.precision == "bfloat16":
        model.bfloat16_rollout()
    if config.compile:
        model.compile_rollout()


def body_from_history(run: Path | None, sim: SimConfig, config: PlannerConfig, timings: Timings) -> FittedBodyDynamics:
    """The body a pilot infers from its own history: fitted (``body="fitted"``) or fitted under
    the prior RUN/body learned (``body="inferred"``; RunError without a run or RUN/body)."""
    if config.body == "fitted":
        return FittedBodyDynamics(sim, config.rigid_substeps, timings, config.fit_frames, config.fit_ridge)
    if run is None:
        raise RunError(
            "body=inferred reads the prior a run learned (RUN/body): name the run, "
            "`orbitmodel eval closed-loop RUN --pilot oracle-true --set body=inferred ...`"
        )
    try:
        inference, learned = load_inference(run)
    except FileNotFoundError as err:
        raise RunError(str(err)) from None
    try:
        return InferredBodyDynamics(inference, learned, sim, config.rigid_substeps, timings, config.fit_frames)
    except ValueError as err:  # the history is longer than the prior was trained on
        raise RunError(f"{run}/body: {err}") from None


def pilot_factory(variant: Variant | str):
    """An ``orbitdata.fly`` factory for ``variant``: ``factory(config, run=None, **planner) -> Pilot``.

    ``make_planner`` below is registered as the ``orbitdata.pilots`` entry point ``planner``, so
    ``orbitdata fly --pilot planner --pilot-option run=RUN --pilot-option preset=cpu --image-size 64``
    flies it. ``preset`` names a planner preset (``plan.config.PLANNER_PRESETS``; default: the
    one that suits the machine, ``plan.config.default_planner_preset``); the other options are PlannerConfig / MPPIConfig / CostConfig field names
    (``samples``, ``horizon``, ``memory_frames``, ...); ``--pilot-option`` passes strings, converted here.
    """

    def factory(config, run: str | None = None, preset: str | None = None, **options) -> PlannerPilot:
        pilot, sim = build_pilot(variant, run, planner_config(preset, **options), config.sim)
        if sim.camera != config.sim.camera:
            raise ValueError(
                f"pilot {Variant(variant).value} needs the run's camera ({sim.camera.image_size} px); "
                "fly it with `orbitmodel eval closed-loop`, which sets it"
            )
        return pilot

    return factory


def make_planner(config, run: str | None = None, preset: str | None = None, **options) -> PlannerPilot:
    """The ``planner`` entry point of ``orbitdata.pilots``: the MPPI planner on a trained run."""
    if run is None:
        raise ValueError("pilot 'planner' needs its run folder: pass --pilot-option run=RUN")
    return pilot_factory(Variant.PLANNER)(config, run, preset, **options)
