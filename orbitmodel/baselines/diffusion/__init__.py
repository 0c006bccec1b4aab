"""Diffusion Policy (Chi et al. 2023), the baseline flown beside the learned planner.

    orbitmodel train-policy DATASET --preset cpu --out RUN
    orbitmodel eval policy RUN DATASET          # action MSE on held-out expert windows
    orbitmodel eval expert-floor RUN DATASET    # other RRT* plans of the expert on the same windows
    pilot = load_policy_pilot(RUN)              # an orbitdata pilot: reset(task), act(obs)

Modules: ``config`` (presets), ``sampling`` (how a run is sampled and flown: PolicySampling and the
flight presets), ``unet (ConditionalUnet1D, FiLM), ``encoder`` (observations),
``policy`` (DDPM training, DDIM sampling, EMA), ``train``, ``pilot``, ``evaluate``,
``expert_floor`` (the expert against itself).
Heavy imports (torch, diffusers) happen when a name is first used.
"""

from __future__ import annotations

_EXPORTS = {
    "PolicyConfig": "config",
    "PolicyTrainConfig": "config",
    "PolicyPreset": "config",
    "POLICY_PRESETS": "config",
    "get_policy_preset": "config",
    "ConditionalUnet1D": "unet",
    "DiffusionPolicy": "policy",
    "PolicyRequest": "train",
    "train_policy": "train",
    "read_policy_run": "config",
    "DiffusionPilot": "pilot",
    "load_policy_pilot": "pilot",
    "PolicySampling": "sampling",
    "POLICY_FLIGHTS": "sampling",
    "policy_sampling": "sampling",
    "evaluate_policy": "evaluate",
    "ActionMSE": "evaluate",
    "ExpertFloor": "expert_floor",  # and expert_floor.expert_floor(RUN, DATASET)
}
__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module

    return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
