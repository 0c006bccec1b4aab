"""Way (a) of the dynamic tier: each candidate meets the debris where the depth it imagines puts them."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from scenes import sphere_depth, state_at
from typer.testing import CliRunner

from orbitdata.fly.rollout import fly_episode
from orbitdata.schema import DT
from orbitdata.seeding import grid_seed
from orbitdata.sim.config import CameraConfig, SimConfig
from orbitdata.sim.env import CubeSatEnv
from orbitmodel.cli.app import app
from orbitmodel.config import get_preset
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import PlannerConfig
from orbitmodel.plan.depth_recipe import ImaginedDepthConfig
from orbitmodel.plan.dynamics import LearnedDynamics
from orbitmodel.plan.imagined import ImaginedDepth, ImaginedDepthHead, ImaginedField, outside_view
from orbitmodel.plan.imagined_fit import fit_imagined_depth, load_imagined_depth
from orbitmodel.plan.mppi import MPPIConfig
from orbitmodel.plan.obstacles import Camera, PointCloud
from orbitmodel.plan.pilot import PlannerPilot, Variant
from orbitmodel.runs import RunError

torch.set_num_threads(1)
CAMERA = Camera.from_sim(SimConfig())
STEP, STEPS = 5, 10  # a world model stepping 5 frames, a 50-frame plan
RADIUS = 0.5


def sphere_at(t: float) -> np.ndarray:
    """A sphere crossing into the path: (3.5, 1.5, 0) m at t = 0, drifting -y at 0.75 m/s."""
    return np.array([3.5, 1.5 - 0.75 * t, 0.0])


def candidate(speed: float) -> torch.Tensor:
    """(H, 16) imagined states of a body flying +x at ``speed`` m/s from the origin (identity attitude)."""
    return torch.stack([torch.tensor(state_at((speed * (h + 1) * DT, 0.0, 0.0))) for h in range(STEPS * STEP)])


def imagined_maps(states: torch.Tensor) -> torch.Tensor:
    """(S, 16, 16): what a perfect imagination sees at the end of each step, from where it is then."""
    maps = []
    for j in range(STEPS):
        frame = (j + 1) * STEP - 1
        t = (frame + 1) * DT
        maps.append(sphere_depth(CAMERA, states[frame, :3].numpy(), [(sphere_at(t), RADIUS)]))
    return torch.tensor(np.stack(maps), dtype=torch.float32)


def test_each_candidate_meets_the_sphere_where_it_will_be_not_where_it_was():
    states = torch.stack([candidate(1.0), candidate(0.5)])  # (2, H, 16): two candidates, two futures
    maps = torch.stack([imagined_maps(s) for s in states])  # (2, S, 16, 16)
    field = ImaginedField(maps, states, STEP, CAMERA, max_range=10.0)
    positions = states[..., :3]
    got = field.clearance(positions)  # (2, H)
    times = (torch.arange(STEPS * STEP) + 1) * DT
    exact = (positions - torch.tensor(np.stack([sphere_at(float(t)) for t in times]), dtype=torch.float32)).norm(
        dim=-1
    ) - RADIUS
    seen_from = slice(STEP - 1, None, STEP)  # the frames each map was seen from
    # A surface of cell spheres: within a cell's radius (0.19 m at 2.5 m) of the exact gap.
    assert torch.allclose(got[:, seen_from], exact[:, seen_from], atol=0.25)
    # Frames between two maps meet the later one: the sphere moves at most 0.15 m in a step.
    assert torch.allclose(got, exact, atol=0.25 + 0.75 * STEP * DT)
    # Where the sphere started is 0.6 m off at the end: the field is not the frozen picture.
    frozen = (positions - torch.tensor(sphere_at(0.0), dtype=torch.float32)).norm(dim=-1) - RADIUS
    assert (frozen[0, -1] - got[0, -1]) > 0.4 and (got[0, -1] - exact[0, -1]).abs() < 0.25


def test_cells_beyond_range_are_no_obstacle_and_the_base_adds_what_is_out_of_view():
    states = candidate(1.0)[None]
    far = torch.full((1, STEPS, 16, 16), CAMERA.far)
    behind = PointCloud(np.array([[-1.0, 0.0, 0.0]]), np.array([0.1]), reach=5.0)
    assert torch.isinf(ImaginedField(far, states, STEP, CAMERA, 10.0).clearance(states[..., :3])).all()
    got = ImaginedField(far, states, STEP, CAMERA, 10.0, base=behind).clearance(states[..., :3])
    x = states[0, :, 0]
    assert torch.allclose(got[0], x + 1.0 - 0.1, atol=1e-5)  # the still point behind, as the memory has it


def test_outside_view_keeps_what_the_camera_cannot_see_now():
    state = state_at((0.0, 0.0, 0.0))
    points = np.array(
        [
            [3.0, 0.0, 0.0],  # straight ahead
            [3.0, 2.0, 1.0],  # ahead, inside the 100 deg view
            [-2.0, 0.0, 0.0],  # behind
            [1.0, 3.0, 0.0],  # at the side, beyond 50 deg
            [12.0, 0.0, 0.0],  # ahead, beyond the planner's range
        ]
    )
    assert outside_view(points, state, CAMERA, 10.0).tolist() == [False, False, True, True, True]


# ---- the head, fitted on a world model's own rollouts --------------------------------------------
SMALL = ImaginedDepthConfig(windows=8, test_windows=4, horizon=5, hidden=32, epochs=3, batch_size=8)


@pytest.fixture(scope="module")
def imagined_run(tiny_run, tiny_dataset_master, tmp_path_factory):
    run = tmp_path_factory.mktemp("imagined") / "tiny"
    shutil.copytree(tiny_run, run)
    result = fit_imagined_depth(run, str(tiny_dataset_master), SMALL)
    return run, result


def test_the_fit_writes_a_head_scored_at_each_step_ahead_and_reproduces_from_its_seed(
    imagined_run, tiny_dataset_master, tmp_path
):
    run, result = imagined_run
    scored = json.loads((run / "depth-imagined" / "eval.json").read_text())
    assert [s["step"] for s in scored["steps"]] == list(range(6))  # the encoded frame, then 5 imagined
    assert all(sum(b["cells"] for b in s["bands"]) == 4 * 256 for s in scored["steps"])
    model = WorldModel.from_pretrained(run)
    head = load_imagined_depth(run, model).head
    again = tmp_path / "again"
    shutil.copytree(run, again)
    fit_imagined_depth(again, str(tiny_dataset_master), SMALL, overwrite=True)
    other = load_imagined_depth(again, model).head
    assert all(torch.equal(a, b) for a, b in zip(head.state_dict().values(), other.state_dict().values()))
    with pytest.raises(RunError, match="--overwrite"):
        fit_imagined_depth(run, str(tiny_dataset_master), SMALL)


def test_the_cli_fits_it_and_a_run_without_one_names_the_command(imagined_run, tiny_run, tiny_dataset_master):
    run, _ = imagined_run
    res = CliRunner().invoke(app, ["depth", str(run), str(tiny_dataset_master), "--imagined", "--epochs", "1"])
    assert res.exit_code == 2 and "--overwrite" in res.output and "Traceback" not in res.output
    with pytest.raises(RunError, match="orbitmodel depth .* --imagined"):
        load_imagined_depth(tiny_run, WorldModel.from_pretrained(tiny_run))


class ImagineAll:
    """The probe's API: the state held still, reading the latents (so the rollout imagines them)."""

    config = type("C", (), {"reads_latent": True})()

    def per_frame(self, z_future, state0, z_last, frame_step, actions=None):
        return state0[:, None].expand(-1, z_future.shape[1] * frame_step, -1).clone()


def test_the_imagined_planner_costs_each_candidate_against_its_own_imagined_maps():
    sim = SimConfig(camera=CameraConfig(image_size=64), max_steps=6)
    model = WorldModel(get_preset("tiny").model).eval()
    torch.manual_seed(0)
    head = ImaginedDepthHead(model.config.latent_dim, 16)
    config = PlannerConfig(mppi=MPPIConfig(samples=8, horizon=5), obstacle_motion="imagined")
    wall = np.full((16, 16), 3.0)  # a wall 3 m ahead in every frame: points in view
    pilot = PlannerPilot(
        Variant.PLANNER,
        LearnedDynamics(model, ImagineAll()),
        lambda obs: wall,
        Camera.from_sim(sim),
        config,
        sim,
        imagined=ImaginedDepth(head, 50.1),
    )
    fields, clouds = [], []
    round_field, obstacles = pilot.round_field, pilot._obstacles
    pilot.round_field = lambda f, s: fields.append(round_field(f, s)) or fields[-1]
    pilot._obstacles = lambda obs, depth: clouds.append((obs["state"], obstacles(obs, depth))) or clouds[-1][1]
    result = fly_episode(CubeSatEnv(sim), pilot, grid_seed(0, 3, 1.0, 0), 3, 1.0)
    assert result.length == 6 and fields and all(isinstance(f, ImaginedField) for f in fields)
    field = fields[-1]
    z = pilot.dynamics.imagined_latents  # (K, 5, D): the last round's
    with torch.no_grad():
        assert torch.equal(field.keep.reshape(8, 5, 16, 16), head(z) * 50.1 < 10.0)
    # The memory holds the wall's points; what the camera sees now, the imagined maps alone stand for.
    remembered, (last, _) = pilot.memory.cloud().points, clouds[-1]
    assert not outside_view(remembered, last, pilot.camera, config.max_range).all()
    for state, cloud in clouds:
        assert len(cloud.points) == 0 or outside_view(cloud.points, state, pilot.camera, config.max_range).all()
    assert len(fields) == len(clouds) and all(f.base is c for f, (_, c) in zip(fields, clouds))  # one round a replan
    with pytest.raises(ValueError, match="imagined"):  # a head without the setting, or the setting without one
        PlannerPilot(
            Variant.PLANNER, pilot.dynamics, pilot.depth, pilot.camera, PlannerConfig(), sim, imagined=pilot.imagined
        )
