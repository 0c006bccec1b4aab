"""``CubeSat-v1``: the simulator as a registered Gymnasium environment (the ``gym`` extra).

    import gymnasium as gym
    import orbitdata.sim.gym                          # registers CubeSat-v1
    env = gym.make("CubeSat-v1", n_obstacles=3, speed=2.0, image_size=64)
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    info["outcome"]                                   # None while flying; success, collision, timeout, out_of_fuel

``gym.make("orbitdata.sim.gym:CubeSat-v1", ...)`` imports and registers in one call.

Spec (the same world and episodes as :class:`orbitdata.sim.env.CubeSatEnv` and the dataset):

* **Action**: ``Box(0, 1, (8,), float32)``, the normalised thrust of thrusters 0..7, held for
  one control step of 0.04 s. Values outside [0, 1], NaN or Inf raise ``ValueError``.
* **Observation**: ``Dict`` of ``state`` (16,) float32 ``[p, v_body, rot6d, w_body, fuel]``
  (``orbitdata.state``), ``goal`` (3,) float32 metres, world frame relative to the start (as p),
  and, unless ``images=False``, ``image`` (S, S, 3) uint8 RGB and ``depth`` (S, S) float32 metres
  along the optical axis (0 = no return) from the onboard camera.
* **Episode end**: ``terminated`` on a collision, on entering the 0.5 m goal sphere
  (``success``) or with an empty tank (``out_of_fuel``); ``truncated`` at frame 299 (``timeout``,
  12 s). **Reward**: +1 on success, -1 on a collision, 0 otherwise.
* **info**: ``outcome`` (None while flying), ``collision``, ``success``, ``min_clearance`` (m),
  ``fuel_kg``, ``mass``, ``thrust`` (after fuel limits), ``position_world``, ``step``, and
  ``episode_seed``: the seed that drew the episode's world (obstacles, goal, initial velocity,
  attitude, lighting), so ``reset(seed=episode_seed)`` flies it again.
* **Arguments** (``gym.make`` keywords): ``n_obstacles`` and ``speed`` (m/s) fix those draws of
  every episode (None: drawn from the scenario's ranges, 1-5 obstacles, 0.5-2.5 m/s); ``image_size``
  (px, square); ``seed``: the first ``reset``'s seed when it is given none; ``images``: render the
  camera (False: state and goal only, much faster); ``max_steps``; ``sim`` and ``scenario``: the
  full :class:`~orbitdata.sim.config.SimConfig` and :class:`~orbitdata.scenario.config.ScenarioConfig`
  (a dataset's are in its ``meta/info.json``). ``reset(options=...)`` takes ``n_obstacles``,
  ``speed`` or a whole ``scenario`` for one episode.

Version history: v1, the simulator of dataset schema 1.0.
"""

from __future__ import annotations

import dataclasses

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
except ImportError:  # the optional extra
    raise ImportError("CubeSat-v1 as a Gymnasium environment needs gymnasium: pip install 'orbitdata[gym]'") \
        from None

from orbitdata.scenario.config import ScenarioConfig
from orbitdata.schema import ACTION_DIM, STATE_DIM
from orbitdata.sim.config import SimConfig
from orbitdata.sim.env import CubeSatEnv

ENV_ID = CubeSatEnv.version  # "CubeSat-v1"
SEED_BOUND = 2**63 - 1  # episode seeds drawn by reset() without one


class CubeSatGymEnv(gymnasium.Env):
    """:class:`CubeSatEnv` behind Gymnasium's API and spaces (see the module docstring for the spec)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, n_obstacles: int | None = None, speed: float | None = None, image_size: int | None = None,
                 seed: int | None = None, images: bool = True, max_steps: int | None = None,
                 sim: SimConfig | None = None, scenario: ScenarioConfig | None = None, render_mode: str | None = None):
        sim = sim or SimConfig()
        camera = sim.camera if image_size is None else dataclasses.replace(sim.camera, image_size=int(image_size))
        sim = dataclasses.replace(sim, camera=camera, render=bool(images), max_steps=max_steps or sim.max_steps)
        if render_mode not in (None, "rgb_array") or (render_mode and not images):
            raise ValueError(f"render_mode={render_mode!r}: CubeSat-v1 renders 'rgb_array' (with images=True) only")
        self.env = CubeSatEnv(sim, scenario or ScenarioConfig())
        self.n_obstacles, self.speed, self.render_mode = n_obstacles, speed, render_mode
        self._first_seed = seed  # the first reset's, when it is given none
        self._reset_before = False
        s = camera.image_size
        observations = {"state": spaces.Box(-np.inf, np.inf, (STATE_DIM,), np.float32),
                        "goal": spaces.Box(-np.inf, np.inf, (3,), np.float32)}
        if images:
            observations["image"] = spaces.Box(0, 255, (s, s, 3), np.uint8)
            observations["depth"] = spaces.Box(0.0, float(camera.far), (s, s), np.float32)
        self.observation_space = spaces.Dict(observations)
        self.action_space = spaces.Box(0.0, 1.0, (ACTION_DIM,), np.float32)
        self._image: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is None and not self._reset_before:
            seed = self._first_seed
        self._reset_before = True
        super().reset(seed=seed)  # seeds self.np_random, which draws the episodes of resets given no seed
        episode_seed = seed if seed is not None else int(self.np_random.integers(SEED_BOUND))
        options = {"n_obstacles": self.n_obstacles, "speed": self.speed, **(options or {})}
        if options.get("scenario") is not None:
            options = {"scenario": options["scenario"]}
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
        out = {"state": obs["state"].astype(np.float32),
               "goal": np.asarray(self.env.scenario.goal, dtype=np.float32)}
        if "image" in obs:
            out["image"], out["depth"] = obs["image"], obs["depth"].astype(np.float32)
            self._image = obs["image"]
        return out

    def _info(self, info: dict) -> dict:
        return {**info, "episode_seed": self._episode_seed}


if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point=f"{__name__}:CubeSatGymEnv")
