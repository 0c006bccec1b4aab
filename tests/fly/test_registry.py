"""Pilots by name: built-ins, pilots registered from outside orbitdata (in process and by entry
point), the flight grid with a factory and the render flag, and what a non-privileged pilot sees."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from stub_pilot import SeeingPilot, make_stub
from typer.testing import CliRunner

from orbitdata.cli.app import app
from orbitdata.config import GenerationConfig
from orbitdata.fly import Pilot, fly_grid, list_pilots, make_pilot, register_pilot, registry

runner = CliRunner()
HERE = Path(__file__).parent
TINY = GenerationConfig().replace(sim={"camera": GenerationConfig().sim.camera.__class__(image_size=32)})
FLIGHT = TINY.flight  # what flying reads: sim, scenario, pilots


@pytest.fixture
def stub_registered(monkeypatch):
    monkeypatch.setattr(registry, "_FACTORIES", dict(registry._FACTORIES))
    register_pilot("stub", make_stub)
    return "stub"


def check_sees_images_not_obstacles(episodes: list[dict], size: int, depth: bool = False) -> None:
    """It saw the camera and its state, the rendered depth only if it declared ``sees_depth``,
    and never the ground truth."""
    assert episodes and all(ep["steps"] > 0 for ep in episodes)
    for ep in episodes:
        assert ep["keys"] == (["depth", "depth_low", "image", "state"] if depth else ["image", "state"])
        assert ep["image"] == [[size, size, 3, "uint8"]]
        if depth:
            assert ep["depth"] == [[size, size, "float32"]] and ep["depth_low"] == [[16, 16, "float32"]]
        assert ep["ground_truth"] == []
        assert set(ep["task"]) == {"goal", "goal_radius", "initial_velocity", "seed"}


def test_the_built_in_levels_are_listed_first_and_made_by_name():
    assert list_pilots()[:3] == ("expert", "risky", "exploratory")
    for name in ("expert", "risky", "exploratory"):
        pilot = make_pilot(name)
        assert isinstance(pilot, Pilot) and pilot.name == name
    assert make_pilot("expert").privileged and not make_pilot("risky").privileged
    with pytest.raises(ValueError, match="unknown pilot 'reckless'; expected one of expert, risky"):
        make_pilot("reckless")


def test_registering_checks_names_and_clashes(stub_registered):
    assert "stub" in list_pilots()
    with pytest.raises(ValueError, match="already registered"):
        register_pilot("stub", make_stub)
    with pytest.raises(ValueError, match="pilot name"):
        register_pilot("two words", make_stub)
    register_pilot("broken", lambda config: object())
    with pytest.raises(TypeError, match="not an orbitdata.fly.Pilot"):
        make_pilot("broken")


def test_a_registered_pilot_flies_the_grid_with_rendering(stub_registered, tmp_path):
    log = tmp_path / "seen.json"
    cells = fly_grid("stub", [1], [2.0], 2, config=FLIGHT, log=str(log))
    assert sum(c.success + c.collision + c.timeout + c.out_of_fuel for c in cells) == 2
    check_sees_images_not_obstacles(json.loads(log.read_text()), 32)


def test_only_a_pilot_that_declares_it_sees_the_rendered_depth(tmp_path):
    """The rendered depth is a perfect sensor: a camera-only pilot is not handed it."""

    class DepthSensing(SeeingPilot):
        sees_depth = True

    for cls, depth in ((SeeingPilot, False), (DepthSensing, True)):
        log = tmp_path / f"{cls.__name__}.json"
        fly_grid(lambda config, cls=cls, log=log: cls(str(log)), [1], [1.0], 1, config=FLIGHT)
        check_sees_images_not_obstacles(json.loads(log.read_text()), 32, depth=depth)


def test_fly_grid_takes_a_factory_and_one_pilot_flies_every_episode(tmp_path):
    made: list[SeeingPilot] = []

    def factory(config):
        made.append(SeeingPilot())
        return made[-1]

    fly_grid(factory, [0, 1], [1.0], 2, config=FLIGHT)
    assert len(made) == 1 and len(made[0].episodes) == 4
    with pytest.raises(ValueError, match="needs camera images"):
        fly_grid(factory, [0], [1.0], 1, config=FLIGHT, render=False)


def test_a_pilot_of_the_wrong_arguments_or_action_is_named():
    from orbitdata.fly.rollout import fly_episode
    from orbitdata.sim import CubeSatEnv

    with pytest.raises(TypeError, match=r"pilot 'expert': got an unexpected keyword argument 'foo'"):
        make_pilot("expert", foo=1)

    class Short(Pilot):
        name = "short"

        def reset(self, task, **kwargs):
            pass

        def act(self, obs):
            return np.zeros(7)

    env = CubeSatEnv(TINY.sim.__class__(render=False, max_steps=3))
    try:
        with pytest.raises(ValueError, match=r"pilot 'short' gave an action of shape \(7,\) at frame 0: give 8"):
            fly_episode(env, Short(), seed=0)
        for seed in (None, 1.5):
            with pytest.raises(ValueError, match="seed"):
                fly_episode(env, Short(), seed=seed)
    finally:
        env.close()


def test_only_a_privileged_pilot_gets_the_scenario():
    from orbitdata.fly.rollout import fly_episode
    from orbitdata.sim import CubeSatEnv

    class Spy(Pilot):
        name = "spy"

        def __init__(self, privileged):
            self.privileged, self.calls = privileged, []

        def reset(self, task, **kwargs):
            self.calls.append(sorted(kwargs))

        def act(self, obs):
            return np.zeros(8)

    env = CubeSatEnv(TINY.sim.__class__(render=False, max_steps=3))
    try:
        for privileged, expected in ((False, []), (True, ["scenario"])):
            spy = Spy(privileged)
            fly_episode(env, spy, seed=0, n_obstacles=2, speed=1.0)
            assert spy.calls == [expected]
    finally:
        env.close()


def test_orbitdata_fly_flies_a_registered_pilot_that_sees(stub_registered, tmp_path):
    log = tmp_path / "seen.json"
    res = runner.invoke(
        app,
        [
            "fly",
            "--pilot",
            "stub",
            "--obstacles",
            "1",
            "--speeds",
            "2",
            "--episodes",
            "1",
            "--image-size",
            "32",
            "--pilot-option",
            f"log={log}",
            "--json",
            str(tmp_path / "g.json"),
        ],
    )
    assert res.exit_code == 0, res.output
    check_sees_images_not_obstacles(json.loads(log.read_text()), 32)
    assert json.loads((tmp_path / "g.json").read_text())["pilot"] == "stub"
    res = runner.invoke(app, ["fly", "--pilot", "stub", "--episodes", "1", "--pilot-option", "speed=3"])
    assert res.exit_code == 2 and "--pilot-option" in res.output and "speed" in res.output
    res = runner.invoke(app, ["fly", "--pilot", "stub", "--episodes", "1", "--no-render"])  # it reads the camera
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and lines == ["error: pilot 'stub' reads the camera: drop --no-render"], res.output


def test_an_entry_point_pilot_flies_the_real_command(tmp_path):
    """Another package's pilot, found through its `orbitdata.pilots` entry point, in a fresh process."""
    dist = tmp_path / "site" / "stubpkg-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: stubpkg\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{registry.ENTRY_POINT_GROUP}]\nstub = stub_pilot:make_stub\n")
    import orbitdata  # the subprocess runs this same orbitdata, whatever is installed

    paths = [str(dist.parent), str(HERE), str(Path(orbitdata.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in paths if p))
    cmd = [sys.executable, "-m", "orbitdata", "fly"]
    help_text = subprocess.run(
        [*cmd, "--help"], env=env, capture_output=True, text=True, timeout=120, check=True
    ).stdout
    assert "stub" in help_text
    log = tmp_path / "seen.json"
    res = subprocess.run(
        [
            *cmd,
            "--pilot",
            "stub",
            "--obstacles",
            "1",
            "--speeds",
            "2",
            "--episodes",
            "1",
            "--image-size",
            "32",
            "--pilot-option",
            f"log={log}",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    check_sees_images_not_obstacles(json.loads(log.read_text()), 32)


def test_image_quality_hands_the_pilot_the_datasets_jpeg_of_its_camera():
    """--image-codec: the pilot sees each frame as the dataset would store it (JPEG at the config's
    quality); the raw render is what it sees without, and what the frame sink always gets."""
    from orbitdata.codecs import decode_rgb, encode_rgb

    class Recorder(SeeingPilot):
        def act(self, obs):
            self.images.append(obs["image"].copy())
            return np.zeros(8)

    for codec in (False, True):
        pilot, raw = Recorder(), []
        pilot.images = []
        quality = TINY.dataset.jpeg_quality
        fly_grid(
            lambda config: pilot,
            [1],
            [1.0],
            1,
            config=TINY.replace(sim={"max_steps": 4}).flight,
            image_quality=quality if codec else None,
            frame_sink=lambda t, rgb, *_: raw.append(rgb.copy()),
        )
        expected = [decode_rgb(encode_rgb(r, quality)) if codec else r for r in raw[: len(pilot.images)]]
        assert len(pilot.images) == 3 and all(np.array_equal(a, b) for a, b in zip(pilot.images, expected))
        assert codec == any(not np.array_equal(a, r) for a, r in zip(pilot.images, raw))
