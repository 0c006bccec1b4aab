"""Planning: MPPI over thrust sequences on imagined futures (``orbitmodel.plan``).

    from orbitmodel.plan import MPPI, MPPIConfig, PlannerConfig, Variant, build_pilot, planner_config

* :mod:`~orbitmodel.plan.config`: PlannerConfig and the named planner presets (``paper``, ``cpu``);
* :mod:`~orbitmodel.plan.mppi`: the sampler, generic over a cost ``(K, H, 8) -> (K,)``;
* :mod:`~orbitmodel.plan.dynamics`: the world model + probe, and the rigid-body oracle;
* :mod:`~orbitmodel.plan.frames`: one encoder pass per observed frame, shared by dynamics and depth;
* :mod:`~orbitmodel.plan.obstacles`: depth -> world points, and the true obstacles (oracles);
* :mod:`~orbitmodel.plan.tracker`: depth points clustered into moving tracks (``obstacle_motion="tracker"``);
* :mod:`~orbitmodel.plan.depth_refit`: the depth head refitted for near cells (``orbitmodel depth``),
  scored by :mod:`~orbitmodel.plan.depth_bands`;
* :mod:`~orbitmodel.plan.fitted_body` and :mod:`~orbitmodel.plan.inferred_body`: the body inferred
  from the pilot's own history (``body="fitted"``; ``"inferred"``, under a prior ``orbitmodel body``
  learns, its recipe in :mod:`~orbitmodel.plan.body_recipe`);
* :mod:`~orbitmodel.plan.cost`: collision, progress, effort, spin, heading, speed;
* :mod:`~orbitmodel.plan.pilot`: the pilots (``orbitdata.fly`` interface) and their variants;
* :mod:`~orbitmodel.plan.batch`: one control step of several pilots at once (lockstep flights);
* :mod:`~orbitmodel.plan.factory`: a pilot from a run folder.

Names import on first use (MuJoCo and the model load only when needed).
"""

_LAZY = {
    "MPPI": "orbitmodel.plan.mppi",
    "MPPIConfig": "orbitmodel.plan.mppi",
    "CostConfig": "orbitmodel.plan.cost",
    "trajectory_cost": "orbitmodel.plan.cost",
    "LearnedDynamics": "orbitmodel.plan.dynamics",
    "RigidBodyDynamics": "orbitmodel.plan.dynamics",
    "Camera": "orbitmodel.plan.obstacles",
    "PointCloud": "orbitmodel.plan.obstacles",
    "TrueObstacles": "orbitmodel.plan.obstacles",
    "depth_to_points": "orbitmodel.plan.obstacles",
    "Tracker": "orbitmodel.plan.tracker",
    "TrackerConfig": "orbitmodel.plan.tracker",
    "PlannerConfig": "orbitmodel.plan.config",
    "PLANNER_PRESETS": "orbitmodel.plan.config",
    "planner_config": "orbitmodel.plan.config",
    "default_planner_preset": "orbitmodel.plan.config",
    "DepthRefitConfig": "orbitmodel.plan.depth_refit",
    "refit_depth_head": "orbitmodel.plan.depth_refit",
    "PlannerPilot": "orbitmodel.plan.pilot",
    "OraclePilot": "orbitmodel.plan.pilot",
    "plan_batch": "orbitmodel.plan.batch",
    "Variant": "orbitmodel.plan.variant",
    "build_pilot": "orbitmodel.plan.factory",
    "pilot_factory": "orbitmodel.plan.factory",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'orbitmodel.plan' has no attribute {name!r}")


__all__ = sorted(_LAZY)
