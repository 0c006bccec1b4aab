"""``CubeSat-v1``: the simulator as a registered Gymnasium environment (the ``gym`` extra).

    import gymnasium as gym
    import orbitdata.sim.gym                          # registers CubeSat-v1
    env = gym.make("CubeSat-v1", n_obstacles=3, speed=2.0, image_size=64)
    env = gym.make("CubeSat-v1", tier="dynamic")      # drifting debris, CW terms, faults, noisy camera
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    info["outcome"]                                   # None while flying; success, collision, timeout, out_of_fuel
                                                      # (and tumbling on the dynamic tier)

``gym.make("orbitdata.sim.gym:CubeSat-v1", ...)`` imports and registers in one call.

Spec (the same world and episodes as :class:`orbitdata.sim.env.CubeSatEnv` and the dataset):

* **Action**: ``Box(0, 1, (8,), float32)``, the normalised thrust of thrusters 0..7, held for
  one control step of 0.04 s. Values outside [0, 1], NaN or Inf raise ``ValueError``.
* **Observation**: a ``Dict`` keyed by the dataset's column names, with the values a dataset row
  decodes to (``orbitdata.schema``), so a policy trained on the dataset reads the env unchanged:
  ``observation.state`` (16,) float32 ``[p, v_body, rot6d, w_body, fuel]`` (``orbitdata.state``),
  ``goal`` (3,) float32 metres, world frame relative to the start (as p; the episodes table's
  ``goal``), and, unless ``images=False``, ``observation.image`` (S, S, 3) uint8 RGB,
  ``observation.depth`` (S, S) float32 metres along the optical axis (0 = no return) and
  ``observation.depth_low`` (16, 16) float32 metres (no return counts as the far plane). The
  dataset stores the image as JPEG and the depth in whole millimetres; the env hands over the
  render itself.
* **Episode end**: ``terminated`` on a collision, on entering the 0.5 m goal sphere
  (``success``) or with an empty tank (``out_of_fuel``); ``truncated`` after ``max_steps`` steps
  (``timeout``; by default 299 steps, 12 s: the dataset's episodes of at most 300 frames). On
  ``tier="dynamic"`` also ``terminated`` when the body spins faster than 35 rad/s
  (``tumbling``, ``DynamicConfig.max_body_rate``). **Reward**: +1 on success, -1 on a collision, 0 otherwise.
* **info**: ``outcome`` (None while flying), ``collision``, ``success``, ``min_clearance`` (m),
  ``fuel_kg``, ``mass``, ``thrust`` (after fuel limits), ``position_world``, ``step``, and
  ``episode_seed``: the seed that drew the episode's world (obstacles, goal, initial velocity,
  attitude, lighting), so ``reset(seed=episode_seed)`` flies it again, and ``obstacle_poses``
  (N, 7), every obstacle's centre and quat at this frame: privileged, for oracles and checks.
  The observation never carries an obstacle pose.
* **Arguments** (``gym.make`` keywords, checked there): ``tier``: the scenario tier, ``static``
  (the paper's scenes, the default) or ``dynamic`` (drifting, tumbling debris mostly aimed at the
  straight path, Clohessy-Wiltshire terms, a varied body, a faulty thruster, RGB noise and depth
  dropout, eclipses; ``ScenarioConfig.for_tier``); ``n_obstacles`` (a whole number >= 0) and
  ``speed`` (m/s, >= 0) fix those draws of every episode (None: drawn from the tier's ranges,
  1-5 obstacles and 0.5-2.5 m/s static, 1-10 and 0.5-3 m/s dynamic); ``image_size`` (px, square, a multiple of 16); ``seed``: the first
  ``reset``'s seed when it is given none; ``images``: render the camera (False: state and goal
  only, much faster, and no ``render_mode``); ``max_steps``: ``step`` calls before ``truncated``
  (None: the simulator's frame limit less one); ``sim`` and ``scenario``: the full
  :class:`~orbitdata.sim.config.SimConfig` and :class:`~orbitdata.scenario.config.ScenarioConfig`
  (a dataset's are in its ``meta/info.json``; a ``scenario`` of another tier than ``tier`` is refused). ``reset(options=...)`` takes ``n_obstacles``,
  ``speed``, or an episode's whole ``scenario`` alone (``info["episode_seed"]`` is then the seed that
  drew it).
* **Vector envs**: ``gym.make_vec("CubeSat-v1", num_envs=N, vectorization_mode="async")`` works in
  a process that has rendered already: the renderer releases its OpenGL state before a fork
  (``orbitdata.sim.gl``).

Version history: v1, the simulator of dataset schema 1.0. The observation keys took the dataset's
column names, ``observation.depth_low`` was added and ``max_steps`` became the number of steps
(it had counted frames) with the simulator unchanged. ``tier`` was added with the static tier's
episodes unchanged (``info`` gained ``obstacle_poses``).
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
except ImportError:  # the optional extra
    raise ImportError("CubeSat-v1 as a Gymnasium environment needs gymnasium: pip install 'orbitdata[gym]'") from None

from orbitdata import schema as S
from orbitdata.scenario.config import MAX_OBSTACLES, STATIC, TIERS, ScenarioConfig
from orbitdata.scenario.spec import Scenario
from orbitdata.sim.config import SimConfig
from orbitdata.sim.env import CubeSatEnv

ENV_ID = CubeSatEnv.version  # "CubeSat-v1"
SEED_BOUND = 2**63 - 1  # episode seeds drawn by reset() without one
KEYS = {"state": S.STATE, "image": S.IMAGE, "depth": S.DEPTH, "depth_low": S.DEPTH_LOW}  # simulator -> dataset


OBSTACLE_COUNT = f"a whole number of obstacles from 0 to {MAX_OBSTACLES}"


def _whole(name: str, value, low: int, what: str, none: str | None = None, high: int | None = None):
    """``value`` as an int from ``low`` to ``high`` (None: no upper end), or None when ``none`` says
    what None means; else ValueError naming it."""
    if value is None and none is not None:
        return None
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Integral)
        or value < low
        or (high is not None and value > high)
    ):
        raise ValueError(f"{name}={value!r}: give {what}" + (f", or None {none}" if none else ""))
    return int(value)


def _speed(value, name: str = "speed") -> float | None:
    """An initial speed in m/s (finite, >= 0) or None; else ValueError naming it."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise ValueError(f"{name}={value!r}: give a finite speed >= 0 in m/s, or None to draw it per episode")
    return float(value)


class CubeSatGymEnv(gymnasium.Env):
    """:class:`CubeSatEnv` behind Gymnasium's API and spaces (see the module docstring for the spec)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(
        self,
        n_obstacles: int | None = None,
        speed: float | None = None,
        image_size: int | None = None,
        seed: int | None = None,
        images: bool = True,
        max_steps: int | None = None,
        sim: SimConfig | None = None,
        scenario: ScenarioConfig | None = None,
        render_mode: str | None = None,
        tier: str | None = None,
    ):
        n_obstacles = _whole("n_obstacles", n_obstacles, 0, OBSTACLE_COUNT, "to draw it per episode", MAX_OBSTACLES)
        speed = _speed(speed)
        image_size = _whole(
            "image_size", image_size, 16, "a whole number of pixels, a multiple of 16", "for the simulator's camera"
        )
        seed = _whole("seed", seed, 0, "a whole number >= 0", "to draw the first episode's seed")
        max_steps = _whole(
            "max_steps", max_steps, 1, "a whole number of steps >= 1", "for the simulator's frame limit less one"
        )
        if not isinstance(images, bool):
            raise ValueError(f"images={images!r}: give True (render the camera) or False (state and goal only)")
        for name, value, cls in (("sim", sim, SimConfig), ("scenario", scenario, ScenarioConfig)):
            if value is not None and not isinstance(value, cls):
                raise ValueError(f"{name}={type(value).__name__}: give an orbitdata {cls.__name__}, or None")
        if tier is not None and tier not in TIERS:
            raise ValueError(f"tier={tier!r}: give one of {', '.join(map(repr, TIERS))}, or None for {STATIC!r}")
        if scenario is None:
            scenario = ScenarioConfig.for_tier(tier or STATIC)
        elif tier is not None and scenario.tier != tier:
            raise ValueError(f"tier={tier!r} but scenario.tier is {scenario.tier!r}: give one of them, or both alike")
        self.metadata = {**self.metadata, "render_modes": ["rgb_array"] if images else []}
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode={render_mode!r}: CubeSat-v1 renders 'rgb_array' (with images=True) only")
        sim = sim or SimConfig()
        camera = sim.camera if image_size is None else dataclasses.replace(sim.camera, image_size=image_size)
        frames = sim.max_steps if max_steps is None else max_steps + 1  # the simulator counts frames
        sim = dataclasses.replace(sim, camera=camera, render=images, max_steps=frames)  # checks the image size
        self.env = CubeSatEnv(sim, scenario)
        self.tier = scenario.tier
        self.n_obstacles, self.speed, self.render_mode = n_obstacles, speed, render_mode
        self._first_seed = seed  # the first reset's, when it is given none
        self._reset_before = False
        s, far = camera.image_size, float(camera.far)
        observations = {
            S.STATE: spaces.Box(-np.inf, np.inf, (S.STATE_DIM,), np.float32),
            S.GOAL: spaces.Box(-np.inf, np.inf, (3,), np.float32),
        }
        if images:
            side = S.DEPTH_LOW_SIDE
            observations[S.IMAGE] = spaces.Box(0, 255, (s, s, 3), np.uint8)
            observations[S.DEPTH] = spaces.Box(0.0, far, (s, s), np.float32)
            # A far patch's mean may round a few ulps past the far plane.
            observations[S.DEPTH_LOW] = spaces.Box(0.0, far * 1.001, (side, side), np.float32)
        self.observation_space = spaces.Dict(observations)
        self.action_space = spaces.Box(0.0, 1.0, (S.ACTION_DIM,), np.float32)
        self._image: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is None and not self._reset_before:
            seed = self._first_seed
        self._reset_before = True
        super().reset(seed=seed)  # seeds self.np_random, which draws the episodes of resets given no seed
        episode_seed = seed if seed is not None else int(self.np_random.integers(SEED_BOUND))
        given = dict(options or {})
        options = {"n_obstacles": self.n_obstacles, "speed": self.speed, **given}
        if options.get("scenario") is not None:
            scenario = given.pop("scenario")
            if not isinstance(scenario, Scenario):
                raise ValueError(
                    f"options['scenario'] is a {type(scenario).__name__}: give an episode's Scenario (such as "
                    "env.unwrapped.env.scenario); a ScenarioConfig goes to gym.make(scenario=...)"
                )
            if given:
                raise ValueError(
                    f"options {sorted(given)} beside options['scenario']: the scenario fixes its episode; give it alone"
                )
            options = {"scenario": scenario}
            episode_seed = scenario.seed  # the seed that drew it
        else:
            options["n_obstacles"] = _whole(
                "options['n_obstacles']", options["n_obstacles"], 0, OBSTACLE_COUNT, "to draw it", MAX_OBSTACLES
            )
            options["speed"] = _speed(options["speed"], "options['speed']")
        obs, info = self.env.reset(seed=int(episode_seed), options=options)
        self._episode_seed = int(episode_seed)
        return self._observation(obs), self._info(info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(np.asarray(action, dtype=np.float64))
        return self._observation(obs), float(reward), bool(terminated), bool(truncated), self._info(info)

    def render(self):
        return None if self.render_mode is None else self._image

    def close(self) -> None:
        self.env.close()

    def _observation(self, obs: dict) -> dict:
        out = {KEYS[key]: value.astype(np.float32) if key != "image" else value for key, value in obs.items()}
        out[S.GOAL] = np.asarray(self.env.scenario.goal, dtype=np.float32)
        self._image = obs.get("image")
        return out

    def _info(self, info: dict) -> dict:
        return {**info, "episode_seed": self._episode_seed}


if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point=f"{__name__}:CubeSatGymEnv")
