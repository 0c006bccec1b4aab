"""Lockstep flights (``eval closed-loop --batch N``) and grids on Ray (``--executor ray``): a batch of
one is the unbatched flight, a batch of N flies the same episodes, an episode that ends mid-batch
keeps its own frames, the policy's episodes board on its chunk clock, and a Ray grid is the local
grid."""

from __future__ import annotations

import dataclasses
import json
import socket

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from orbitdata.fly.rollout import fly_episode
from orbitdata.sim.env import CubeSatEnv
from orbitmodel.baselines.diffusion.config import get_policy_preset
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy
from orbitmodel.cli.app import app
from orbitmodel.evaluate import lockstep
from orbitmodel.evaluate.closed_loop import (
    ClosedLoop,
    ClosedLoopRequest,
    closed_loop_report,
    episode_record,
    pilot_settings,
)
from orbitmodel.evaluate.lockstep import fly_lockstep
from orbitmodel.plan.config import planner_config
from orbitmodel.plan.pilot import Variant
from orbitmodel.runs import POLICY, stage_of

torch.set_num_threads(1)
runner = CliRunner()
GRID = dict(obstacles=(1, 3), speeds=(1.0, 2.0), episodes=2, seed=7)
SMALL = planner_config("cpu", samples=8, horizon=5)


@pytest.fixture(scope="module")
def policy_run(tmp_path_factory):
    """An untrained tiny Diffusion Policy as a run folder: the interface does not care."""
    from test_diffusion_pilot import save_policy_run

    torch.manual_seed(0)
    policy = DiffusionPolicy(get_policy_preset("tiny").model).eval()
    return save_policy_run(policy, tmp_path_factory.mktemp("dp") / "run").path


def request(run, batch: int, **changes) -> ClosedLoopRequest:
    """The test grid for ``run`` (a planner run flies SMALL, a policy run its cpu flight preset)."""
    settings = SMALL if run is None or stage_of(run) != POLICY else pilot_settings(run, "cpu")[0]
    return ClosedLoopRequest(run=run, settings=settings, preset="cpu", max_steps=25, batch=batch, **{**GRID, **changes})


def without_latency(info: dict) -> dict:
    return {k: v for k, v in info.items() if not k.endswith(("ms_median", "ms_p95"))}


def records(req: ClosedLoopRequest) -> list[dict]:
    """The grid's episode records, without the measured latencies."""
    return [without_latency(e) for e in ClosedLoop(req).fly().episodes]


def unbatched(loop: ClosedLoop) -> list:
    """Today's flight: every grid episode in turn, fly_episode with the pilot's own act."""
    env = CubeSatEnv(loop.sim, loop.req.config.scenario)
    try:
        return [
            fly_episode(env, loop.pilot, seed, n, v, image_quality=loop.image_quality) for n, v, _, seed in loop.order
        ]
    finally:
        env.close()


def lockstep_results(loop: ClosedLoop, batch: int) -> list:
    landed = {}
    make_env = lambda: CubeSatEnv(loop.sim, loop.req.config.scenario)  # noqa: E731
    fly_lockstep(loop.pilot, make_env, loop.order, batch, lambda i, r, *_: landed.update({i: r}), loop.image_quality)
    return [landed[i] for i in range(len(loop.order))]


def same_episode(a, b) -> bool:
    arrays = ("states", "actions", "collision", "success", "min_clearance", "depth_low")
    return a.outcome == b.outcome and all(np.array_equal(getattr(a, k), getattr(b, k)) for k in arrays)


@pytest.mark.parametrize("pilot", ["planner", "diffusion"])
def test_a_batch_of_one_is_exactly_the_unbatched_flight(pilot, probed_run, policy_run):
    run = probed_run if pilot == "planner" else policy_run
    loop = ClosedLoop(request(run, batch=1))
    expected, got = unbatched(loop), lockstep_results(loop, 1)
    assert all(same_episode(a, b) for a, b in zip(expected, got)) and len(got) == 8
    assert [without_latency(r.pilot_info) for r in got] == [without_latency(r.pilot_info) for r in expected]
    flown = ClosedLoop(request(run, batch=1)).fly().episodes
    assert [e["frames"] for e in flown] == [r.length for r in expected]
    assert [e["min_clearance_m"] for e in flown] == [float(r.min_clearance.min()) for r in expected]


@pytest.mark.parametrize("variant", [Variant.PLANNER, Variant.ORACLE_LEARNED_DYN, Variant.ORACLE_TRUE_DYN_DEPTH])
def test_a_batch_of_three_flies_the_planners_episodes_bit_for_bit(variant, probed_run):
    """Each episode draws from its own generators, and every batched call computes each episode's
    rows as its own call would: the encoder, the world model, the probe and the depth head on many
    rows either way, the latent of each frame alone. The batch flies every episode as it flies
    alone, to the last bit of every state and thrust."""
    loop = ClosedLoop(dataclasses.replace(request(probed_run, batch=3), variant=variant))
    expected, got = unbatched(loop), lockstep_results(loop, 3)
    assert len(got) == 8 and all(same_episode(a, b) for a, b in zip(expected, got))
    assert len({r.states.tobytes() for r in got}) == 8  # eight flights, not one flown eight times


def test_a_bfloat16_planner_flies_its_episodes_bit_for_bit_in_a_batch_and_records_its_precision(probed_run):
    """``precision=bfloat16`` flies other episodes than float32 (another rounding), and a batch of
    three still flies each as it flies alone; the grid's file records the precision."""
    low = dataclasses.replace(SMALL, precision="bfloat16")
    loop = ClosedLoop(dataclasses.replace(request(probed_run, batch=3), settings=low))
    expected, got = unbatched(loop), lockstep_results(loop, 3)
    assert len(got) == 8 and all(same_episode(a, b) for a, b in zip(expected, got))
    full = unbatched(ClosedLoop(request(probed_run, batch=3)))
    assert any(not np.array_equal(a.actions, b.actions) for a, b in zip(full, got))
    assert closed_loop_report(loop.req, loop.fly())["planner"]["precision"] == "bfloat16"


def test_a_frame_encoded_in_a_batch_gets_the_latent_it_gets_alone():
    """At the flown sizes (an untrained cpu-step5 model), where a product of one row and one of
    several sum in different orders: the frames of a lockstep batch (channels-last in memory when
    stacked) and their latents equal, bit for bit, what the unbatched pilot computes for each."""
    from orbitmodel.config import get_preset
    from orbitmodel.model.world_model import WorldModel
    from orbitmodel.plan.batch import latents
    from orbitmodel.plan.dynamics import LearnedDynamics
    from orbitmodel.plan.frames import encode_frames

    torch.manual_seed(0)
    model = WorldModel(get_preset("cpu-step5").model).eval()
    rng = np.random.default_rng(0)
    obs = [{"image": rng.integers(0, 256, (64, 64, 3), dtype=np.uint8), "state": rng.normal(size=16)} for _ in range(4)]
    with torch.inference_mode():
        cls, patches = encode_frames(model, [o["image"] for o in obs])
        z = latents(model, cls, [torch.as_tensor(o["state"], dtype=torch.float32)[None] for o in obs])
        for i, o in enumerate(obs):
            alone_cls, alone_patches = encode_frames(model, [o["image"]])
            assert torch.equal(cls[i], alone_cls[0]) and torch.equal(patches[i], alone_patches[0])
            dynamics = LearnedDynamics(model, probe=None)
            dynamics.observe(o, None)
            assert torch.equal(z[i], dynamics.context()[0][0])


def test_an_episodes_candidates_imagine_the_same_in_a_batch_at_the_flown_sizes():
    """The world model's rollout and the probe on one episode's 32 candidates give the same bits as
    on those rows stacked with two other episodes' (an untrained cpu-step5 model and probe): what
    lets a lockstep batch fly the unbatched flight, at the sizes the grids fly."""
    from orbitmodel.config import get_preset
    from orbitmodel.model.world_model import WorldModel
    from orbitmodel.probe.config import ProbeConfig
    from orbitmodel.probe.model import PhysicsProbe

    torch.manual_seed(0)
    model = WorldModel(get_preset("cpu-step5").model).eval()
    shape = dict(latent_dim=model.config.latent_dim, hidden=256, layers=2, substeps=5, action_dim=40)
    probe = PhysicsProbe(ProbeConfig(**shape, inputs="latent+change+thrust", integrator="coasting")).eval()
    for p in probe.parameters():  # an untrained probe predicts zero increments; give it some
        torch.nn.init.normal_(p, std=0.05)
    g = torch.Generator().manual_seed(1)
    K, D, A = 32, model.config.latent_dim, model.config.action_dim * model.config.frame_step
    z = torch.randn(3 * K, 2, D, generator=g)
    actions = torch.rand(3 * K, 11, A, generator=g) * 0.3
    state = torch.zeros(3 * K, 16)
    state[:, 6], state[:, 10], state[:, 15] = 1.0, 1.0, 0.9
    with torch.inference_mode():
        alone = model.rollout(z[:K], actions[:K], 2)
        batched = model.rollout(z, actions, 2)
        assert torch.equal(alone, batched[:K])
        read = probe.per_frame(alone, state[:K], z[:K, -1], 5, actions[:K, 1:])
        assert torch.equal(read, probe.per_frame(batched, state, z[:, -1], 5, actions[:, 1:])[:K])


def test_a_bfloat16_rollout_imagines_each_episodes_candidates_alone():
    """In bfloat16 too (``precision=bfloat16``), one episode's 32 candidates imagine the same bits
    alone as stacked with two other episodes' (an untrained cpu-step5 model): a lockstep batch still
    flies each episode as it flies alone."""
    from orbitmodel.config import get_preset
    from orbitmodel.model.world_model import WorldModel

    torch.manual_seed(0)
    model = WorldModel(get_preset("cpu-step5").model).eval().bfloat16_rollout()
    g = torch.Generator().manual_seed(1)
    K, D, A = 32, model.config.latent_dim, model.config.action_dim * model.config.frame_step
    z, actions = torch.randn(3 * K, 2, D, generator=g), torch.rand(3 * K, 11, A, generator=g) * 0.3
    with torch.inference_mode():
        assert torch.equal(model.rollout(z[:K], actions[:K], 2), model.rollout(z, actions, 2)[:K])


def test_a_batch_of_three_flies_the_policys_episodes(policy_run):
    """The policy's denoiser computes one row per episode alone and several in a batch, whose
    products take other kernels: only the float reduction order differs, so no outcome flips on
    this grid, the same frames, the closest approach within 1 mm."""
    run = policy_run
    one, three = records(request(run, batch=1)), records(request(run, batch=3))
    assert [e["seed"] for e in three] == [e["seed"] for e in one]  # reported in grid order
    assert [e["outcome"] for e in three] == [e["outcome"] for e in one]
    assert [e["frames"] for e in three] == [e["frames"] for e in one]
    assert np.allclose([e["min_clearance_m"] for e in three], [e["min_clearance_m"] for e in one], atol=1e-3)


def test_an_episode_that_ends_mid_batch_keeps_its_own_frames():
    """The true oracle reaches the goal after 107 to 149 frames or times out at 150: episodes end
    at different steps, the next grid episode takes the freed slot, and every record is its own."""
    req = dataclasses.replace(
        request(None, batch=3),
        variant=Variant.ORACLE_TRUE,
        max_steps=150,
        settings=planner_config("cpu", samples=32, horizon=25),
    )
    loop = ClosedLoop(req)
    expected, got = unbatched(loop), lockstep_results(loop, 3)
    frames = [r.length for r in expected]
    assert len(set(frames[:3])) > 1 and min(frames) < 150  # the first batch ends at different steps
    assert [r.length for r in got] == frames
    for a, b in zip(expected, got):
        assert b.length == len(b.states) == len(b.actions) == len(b.min_clearance)
        assert b.outcome == a.outcome and not b.actions[-1].any()  # the terminal frame has no action
        assert b.pilot_info["replans"] == b.length - 1  # its own pilot's count, not its slot's
        assert same_episode(a, b)  # bit for bit, as the planner's batches
    flown = ClosedLoop(req).fly().episodes
    assert [e["frames"] for e in flown] == frames
    assert [e["outcome"] for e in flown] == [r.outcome for r in expected]
    assert [
        episode_record(n, v, k, s, r, loop.sim.cubesat)["frames"] for (n, v, k, s), r in zip(loop.order, got)
    ] == frames


def test_the_policy_boards_episodes_on_its_chunk_clock(policy_run, monkeypatch):
    """Episodes that end mid-chunk, beside ones that fly to the frame limit, free their slot
    until the next chunk step, so every denoising pass serves every live episode (staggered
    starts would split each pass into a few episodes per step); each episode flies as alone."""
    from orbitmodel.baselines.diffusion import pilot as policy_pilot

    req = dataclasses.replace(
        request(policy_run, batch=3), obstacles=(5,), speeds=(2.0,), episodes=6, seed=2, max_steps=60
    )
    alone = records(dataclasses.replace(req, batch=1))
    # What the test needs of this grid, not its exact lengths: some end mid-chunk (chunks of 8), some at the limit
    lengths = [e["frames"] for e in alone]
    assert sum(f < 60 and f % 8 for f in lengths) >= 2 and 60 in lengths
    events = []
    act_batch, sample_chunks = policy_pilot.DiffusionPilot.act_batch, policy_pilot.sample_chunks
    monkeypatch.setattr(
        policy_pilot.DiffusionPilot,
        "act_batch",
        staticmethod(
            lambda pilots, observations: events.append(["live", len(pilots)]) or act_batch(pilots, observations)
        ),
    )
    monkeypatch.setattr(
        policy_pilot, "sample_chunks", lambda pilots: events.append(["due", len(pilots)]) or sample_chunks(pilots)
    )
    batched = records(dataclasses.replace(req, batch=3))
    assert [e["outcome"] for e in batched] == [e["outcome"] for e in alone]
    assert [e["frames"] for e in batched] == [e["frames"] for e in alone]
    passes = [(live[1], due[1]) for live, due in zip(events, events[1:]) if live[0] == "live" and due[0] == "due"]
    assert passes and all(due == live for live, due in passes)
    assert {live for live, _ in passes} == {1, 2, 3}  # slots freed and boarded as the grid went on


def test_a_grid_on_ray_is_the_local_grid(probed_run, monkeypatch):
    """Chunks of one batch each (four Ray tasks on a local Ray instance): the same records as the
    local flight with the same batch size, episode for episode."""
    import ray  # the test extra installs it: a broken import fails here, it is not skipped

    monkeypatch.setattr(lockstep, "ROUNDS_PER_CHUNK", 1)
    assert len(lockstep.chunks(8, 2)) == 4
    local = records(request(probed_run, batch=2))
    ray.init(num_cpus=2, include_dashboard=False)
    try:
        remote = records(request(probed_run, batch=2, executor="ray"))
    finally:
        ray.shutdown()
    assert remote == local


def test_the_cli_says_when_bfloat16_is_emulated_on_this_cpu(probed_run, monkeypatch):
    """On a CPU without AVX-512 BF16 or AMX a bfloat16 rollout is emulated and can be slower than
    float32: the flight says so in one line, and flies."""
    grid = ["--obstacles", "1", "--speeds", "1", "--episodes", "1", "--max-steps", "3", "--set", "samples=8"]
    flight = ["eval", "closed-loop", str(probed_run), "--preset", "cpu", *grid, "--set", "horizon=5"]
    monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda: False)
    monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: False)
    res = runner.invoke(app, [*flight, "--set", "precision=bfloat16"])
    assert res.exit_code == 0 and "precision=bfloat16 is emulated" in res.output, res.output
    res = runner.invoke(app, flight)
    assert res.exit_code == 0 and "emulated" not in res.output
    monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda: True)
    res = runner.invoke(app, [*flight, "--set", "precision=bfloat16"])
    assert res.exit_code == 0 and "emulated" not in res.output


def test_the_cli_flies_a_batch_and_keeps_to_fifteen_options(tmp_path):
    import click
    import typer

    command = typer.main.get_command(app).commands["eval"].commands["closed-loop"]
    options = [p for p in command.get_params(click.Context(command)) if isinstance(p, click.Option)]
    assert len(options) <= 15  # --help included (issue 36)
    out = tmp_path / "oracle.json"
    grid = ["--pilot", "oracle-true", "--obstacles", "1", "--speeds", "1,2", "--episodes", "2", "--max-steps", "6"]
    small = ["--set", "samples=8", "--set", "horizon=5"]
    res = runner.invoke(app, ["eval", "closed-loop", *grid, *small, "--batch", "3", "--json", str(out)])
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    assert report["batch"] == 3 and [e["frames"] for e in report["episodes"]] == [6] * 4
    assert [(e["episode"], e["speed"]) for e in report["episodes"]] == [(0, 1.0), (0, 2.0), (1, 1.0), (1, 2.0)]
    res = runner.invoke(app, ["eval", "closed-loop", *grid, "--executor", "ray", "--video", str(tmp_path / "v")])
    assert res.exit_code == 2 and res.output.startswith("error:") and "local executor" in res.output
    res = runner.invoke(app, ["eval", "closed-loop", *grid, "--batch", "0"])
    assert res.exit_code == 2 and "--batch" in res.output
    with socket.socket() as s:  # a port nothing listens on: refused before the flight, not retried for minutes
        s.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{s.getsockname()[1]}"
    res = runner.invoke(app, ["eval", "closed-loop", *grid, "--executor", "ray"], env={"RAY_ADDRESS": address})
    assert res.exit_code == 2 and res.output.startswith(f"error: RAY_ADDRESS {address}: no Ray cluster answers")
