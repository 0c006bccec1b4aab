import pytest

from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig


@pytest.fixture
def physics_env():
    env = CubeSatEnv(SimConfig(render=False))
    yield env
    env.close()


@pytest.fixture
def render_env():
    env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=64)))
    yield env
    env.close()
