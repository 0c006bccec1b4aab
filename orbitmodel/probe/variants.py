"""Named probes of one Stage I run, the probe rows of Table I: each is a change of the run's probe
recipe, trained with ``orbitmodel probe RUN DATA --variant NAME`` into a folder of its own beside
the run's probe (``RUN/probe``, the one the planner reads).

* ``thrust_probe``: the run's own probe, as its preset prescribes (the flown run's reads the
  latents and, in a branch of its own, each step's thrusts: a planner component), ``RUN/probe``.
* ``paper_probe``: the paper's probe: its MLP reads z_k alone (upstream's inputs) and upstream's
  integrator adds its increments from the last context state (p += dp, v += dv in the body frame,
  w += dw, R <- R exp(w dt)), with no increment loss, which upstream does not have. The rest is
  the run's recipe (MLP size, per-frame head, loss weights, windows, epochs), so that the rows
  differ in what they read and how they integrate, not in how long they trained.
* ``thrust_only``: the run's probe with no latent input, retrained: its thrust branch alone, each
  step's thrusts, integrated from the last context state by the run's integrator.
* ``latent_probe-<inputs>-<head>-<loss>``: probes that read no thrusts, the candidates for Table I's
  ``latent_probe`` row, chosen on the run's validation episodes (``orbitmodel eval probe RUN DATA
  --split val``): ``z`` (z_k) or ``change`` ([z_k, z_k - z_{k-1}]); ``frames`` (every frame's
  increments from its step's latent) or ``steps`` (one increment per latent step, interpolated
  between); ``inc`` (the increment loss at weight 100, the ``cpu-step5`` recipe's) or ``noinc``.
"""

from __future__ import annotations

from orbitmodel.config import ProbeRecipe

FLOWN, PAPER, THRUST_ONLY, LATENT = "thrust_probe", "paper_probe", "thrust_only", "latent_probe"
INCREMENT_WEIGHT = 100.0  # the candidates' increment loss: the cpu-step5 recipe's weight


def _candidates() -> dict[str, dict]:
    out = {}
    for tag, inputs in (("change", "latent+change"), ("z", "latent")):
        for head, per_frame in (("frames", True), ("steps", False)):
            for loss, weight in (("inc", INCREMENT_WEIGHT), ("noinc", 0.0)):
                out[f"{LATENT}-{tag}-{head}-{loss}"] = {
                    "inputs": inputs,
                    "per_frame": per_frame,
                    "increment_weight": weight,
                }
    return out


CANDIDATES: dict[str, dict] = _candidates()  # name -> the recipe settings it changes
VARIANTS: dict[str, dict] = {
    FLOWN: {},
    PAPER: {"inputs": "latent", "integrator": "upstream", "increment_weight": 0.0},
    THRUST_ONLY: {"inputs": "thrust"},
    **CANDIDATES,
}


def check_variant(name: str) -> str:
    if name not in VARIANTS:
        raise ValueError(f"probe variant {name!r}: choose one of {', '.join(VARIANTS)}")
    return name


def variant_recipe(recipe: ProbeRecipe, name: str) -> ProbeRecipe:
    """The probe recipe of variant ``name`` on a run whose own probe recipe is ``recipe``."""
    return recipe.with_changes(**VARIANTS[check_variant(name)])


def folder_name(name: str) -> str:
    """The variant's sub-folder of a Stage I run: ``probe`` for the run's own, else ``probe-NAME``."""
    return "probe" if check_variant(name) == FLOWN else f"probe-{name}"


def train_command(run, name: str = FLOWN) -> str:
    """The command that trains variant ``name`` of ``run``'s probe."""
    return f"orbitmodel probe {run} DATASET" + ("" if name == FLOWN else f" --variant {name}")
