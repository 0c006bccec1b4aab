"""The probe's kinematics and model, on synthetic states (no dataset, no world model)."""

import math

import pytest
import torch

from orbitdata import schema as S
from orbitmodel.kinematics import FUEL, ROT, P, V, W, geodesic_angle, hat, matrix_to_rot6d, rot6d_to_matrix
from orbitmodel.kinematics import so3_exp as exp_so3
from orbitmodel.probe.baselines import STATE_ACTION_DIM, StateDynamics, constant_velocity
from orbitmodel.probe.config import ProbeConfig
from orbitmodel.probe.integrator import increments_of, integrate, step
from orbitmodel.probe.model import PhysicsProbe

DT = S.DT


def make_state(B=1, p=(0, 0, 0), v=(0, 0, 0), R=None, w=(0, 0, 0), fuel=0.8) -> torch.Tensor:
    R = torch.eye(3) if R is None else R
    one = torch.cat(
        [
            torch.tensor(p, dtype=torch.float32),
            torch.tensor(v, dtype=torch.float32),
            matrix_to_rot6d(R.float()),
            torch.tensor(w, dtype=torch.float32),
            torch.tensor([fuel]),
        ]
    )
    return one.expand(B, S.STATE_DIM).clone()


def rot_z(angle: float) -> torch.Tensor:
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def random_rotations(n: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    q = torch.linalg.qr(torch.randn(n, 3, 3, generator=g)).Q
    return q * torch.linalg.det(q).sign()[:, None, None]  # det +1


def test_rot6d_round_trip_and_gram_schmidt():
    R = random_rotations(8)
    assert torch.allclose(rot6d_to_matrix(matrix_to_rot6d(R)), R, atol=1e-6)
    skewed = matrix_to_rot6d(R) * 3.0 + 0.01  # not orthonormal: Gram-Schmidt repairs it
    M = rot6d_to_matrix(skewed)
    assert torch.allclose(M.transpose(-1, -2) @ M, torch.eye(3).expand(8, 3, 3), atol=1e-5)
    assert torch.allclose(torch.linalg.det(M), torch.ones(8), atol=1e-5)


def test_exp_so3_matches_the_matrix_exponential_and_is_smooth_at_zero():
    g = torch.Generator().manual_seed(1)
    for scale in (0.0, 1e-6, 1e-3, 0.3, 2.5):
        phi = torch.randn(16, 3, generator=g, dtype=torch.float64) * scale
        assert torch.allclose(exp_so3(phi), torch.linalg.matrix_exp(hat(phi)), atol=1e-12)
    phi = torch.zeros(4, 3, requires_grad=True)
    exp_so3(phi).sum().backward()
    assert torch.isfinite(phi.grad).all()


def test_geodesic_angle_is_the_rotation_angle():
    R = random_rotations(5, seed=3)
    axis = torch.nn.functional.normalize(torch.randn(5, 3, generator=torch.Generator().manual_seed(4)), dim=-1)
    for angle in (1e-4, 0.1, 1.0, 3.0):
        got = geodesic_angle(R, R @ exp_so3(axis * angle))
        assert torch.allclose(got, torch.full((5,), angle), atol=2e-5 if angle > 1e-3 else 1e-5)


def test_constant_rate_rotation():
    """Zero increments from w = (0, 0, 0.5) rad/s: R_k = R_0 Rz(0.5 k dt), w held."""
    rate, n = 0.5, 50
    R0 = random_rotations(1, seed=2)[0]
    out = integrate(make_state(R=R0, w=(0, 0, rate)), torch.zeros(1, n, 10))  # (1, n, 16)
    for k in (1, 10, n):
        want = R0 @ rot_z(rate * k * DT)
        assert torch.allclose(rot6d_to_matrix(out[0, k - 1, ROT]), want, atol=1e-5)
    assert torch.allclose(out[0, :, W], torch.tensor([0, 0, rate]).expand(n, 3))
    # and about any axis: the angle to R_0 grows linearly
    w = torch.tensor([0.3, -0.4, 0.2])
    out = integrate(make_state(R=R0, w=tuple(w.tolist())), torch.zeros(1, n, 10))
    angles = geodesic_angle(R0.expand(n, 3, 3), rot6d_to_matrix(out[0, :, ROT]))
    assert torch.allclose(angles, w.norm() * DT * torch.arange(1, n + 1), atol=1e-5)


def test_constant_thrust_translation():
    """a = 0.2 m/s^2 along body x, no rotation: v_k = v_0 + a k dt, and with dp = v_k dt
    (semi-implicit Euler) p_k = p_0 + v_0 k dt + a dt^2 k (k + 1) / 2."""
    a, n = torch.tensor([0.2, 0.0, 0.0]), 50
    v0 = torch.tensor([0.5, -0.1, 0.0])
    k = torch.arange(1, n + 1, dtype=torch.float32)[:, None]  # (n, 1)
    v = v0 + a * k * DT  # (n, 3) m/s
    inc = torch.zeros(1, n, 10)
    inc[0, :, 3:6] = a * DT
    inc[0, :, 0:3] = v * DT
    out = integrate(make_state(p=(1.0, 2.0, 3.0), v=tuple(v0.tolist())), inc)
    assert torch.allclose(out[0, :, V], v, atol=1e-5)
    want_p = torch.tensor([1.0, 2.0, 3.0]) + v0 * k * DT + a * DT**2 * k * (k + 1) / 2
    assert torch.allclose(out[0, :, P], want_p, atol=1e-5)
    assert torch.allclose(rot6d_to_matrix(out[0, -1, ROT]), torch.eye(3), atol=1e-6)


def test_zero_increments_keep_the_state():
    state = make_state(B=3, p=(1, -2, 0.5), v=(0.3, 0.1, -0.2), R=random_rotations(1)[0], fuel=0.4)
    out = integrate(state, torch.zeros(3, 20, 10))
    assert torch.allclose(out, state[:, None].expand(3, 20, 16), atol=1e-6)
    assert torch.allclose(step(state, torch.zeros(3, 10)), state, atol=1e-6)


def test_rot6d_stays_orthonormal_over_50_steps():
    g = torch.Generator().manual_seed(5)
    B, n = 64, 50
    state = make_state(B)
    state[:, ROT] = matrix_to_rot6d(random_rotations(B, seed=6))
    state[:, W] = torch.randn(B, 3, generator=g) * 2.0  # rad/s
    inc = torch.randn(B, n, 10, generator=g) * 0.2  # large, noisy rate increments
    out = integrate(state, inc)  # (B, n, 16)
    cols = out[..., ROT].unflatten(-1, (3, 2))  # (B, n, 3, 2)
    gram = cols.transpose(-1, -2) @ cols  # (B, n, 2, 2)
    assert torch.allclose(gram, torch.eye(2).expand_as(gram), atol=1e-5)


def test_integrate_equals_repeated_steps_and_clamps_fuel():
    g = torch.Generator().manual_seed(7)
    B, n = 8, 30
    state = make_state(B, fuel=0.05)
    state[:, ROT] = matrix_to_rot6d(random_rotations(B, seed=8))
    state[:, W] = torch.randn(B, 3, generator=g)
    inc = torch.randn(B, n, 10, generator=g) * 0.05
    inc[:, :, 9] = -0.01  # fuel runs out after 5 steps and stays at 0
    out = integrate(state, inc)
    x = state
    for k in range(n):
        x = step(x, inc[:, k])
        assert torch.allclose(out[:, k], x, atol=1e-5)
    assert (out[..., FUEL] >= 0).all() and torch.allclose(out[:, -1, FUEL], torch.zeros(B, 1))


def test_increments_of_true_states_integrate_back_position_velocity_rates():
    g = torch.Generator().manual_seed(9)
    states = make_state(2).unsqueeze(1).repeat(1, 6, 1)
    states[..., :6] += torch.randn(2, 6, 6, generator=g).cumsum(1)
    states[..., W] += torch.randn(2, 6, 3, generator=g)
    out = integrate(states[:, 0], increments_of(states))
    for s in (P, V, W, FUEL):
        assert torch.allclose(out[..., s], states[:, 1:, s], atol=1e-5)


def test_integration_is_float32_under_bf16_autocast():
    state = make_state(4, w=(1.0, 0.5, -0.3))
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = integrate(state, torch.full((4, 50, 10), 1e-3).to(torch.bfloat16))
    assert out.dtype == torch.float32
    cols = out[..., ROT].unflatten(-1, (3, 2))
    assert torch.allclose(cols.transpose(-1, -2) @ cols, torch.eye(2).expand(4, 50, 2, 2), atol=1e-5)


def test_untrained_probe_predicts_zero_increments_and_checks_shapes():
    probe = PhysicsProbe(ProbeConfig(latent_dim=32))
    state = make_state(2, v=(0.4, 0, 0), w=(0, 0, 0.2))
    out = probe(torch.randn(2, 7, 32), state)
    assert out.shape == (2, 7, 16)
    assert torch.allclose(out, integrate(state, torch.zeros(2, 7, 10)))
    with pytest.raises(ValueError, match="expected"):
        probe(torch.randn(2, 7, 16), state)


def test_constant_velocity_coasts():
    R0 = random_rotations(1, seed=10)[0]
    state = make_state(1, p=(1, 0, 0), v=(0.5, -0.2, 0.1), R=R0, w=(0.1, 0.4, -0.3), fuel=0.7)
    out = constant_velocity(state, 50)  # (1, 50, 16)
    u0 = R0 @ state[0, V]  # m/s, world frame
    R = rot6d_to_matrix(out[0, :, ROT])  # (50, 3, 3)
    assert torch.allclose((R @ out[0, :, V, None]).squeeze(-1), u0.expand(50, 3), atol=1e-5)  # world velocity held
    assert torch.allclose(out[0, -1, P], state[0, P] + 50 * DT * u0, atol=1e-5)
    assert torch.allclose(out[0, :, W], state[0, W].expand(50, 3)) and (out[0, :, FUEL] == 0.7).all()


def test_state_only_model_rolls_out():
    model = StateDynamics(ProbeConfig(kind="state", latent_dim=STATE_ACTION_DIM))
    state = make_state(3, v=(0.2, 0, 0))
    out = model(state, torch.rand(3, 9, S.ACTION_DIM))
    assert out.shape == (3, 9, 16)
    assert torch.allclose(out, integrate(state, torch.zeros(3, 9, 10)))  # untrained: zero increments
    with pytest.raises(ValueError):
        StateDynamics(ProbeConfig(latent_dim=32))


@pytest.mark.parametrize("coasting", [False, True])
def test_both_integrators_agree_with_their_step_and_invert_their_increments(coasting):
    g = torch.Generator().manual_seed(11)
    B, n = 6, 25
    state = make_state(B, v=(1.0, 0.2, -0.3), w=(0.2, -0.1, 0.4))
    state[:, ROT] = matrix_to_rot6d(random_rotations(B, seed=12))
    inc = torch.randn(B, n, 10, generator=g) * 0.05
    out = integrate(state, inc, coasting=coasting)
    x = state
    for k in range(n):
        x = step(x, inc[:, k], coasting=coasting)
        assert torch.allclose(out[:, k], x, atol=1e-5)
    trajectory = torch.cat([state[:, None], out], dim=1)
    assert torch.allclose(
        integrate(state, increments_of(trajectory, coasting=coasting), coasting=coasting), out, atol=1e-5
    )


def test_coasting_with_zero_increments_is_constant_velocity():
    state = make_state(3, p=(0.5, 0, 0), v=(1.5, 0.1, 0), R=random_rotations(1, seed=13)[0], w=(0.3, 0, -0.2))
    assert torch.allclose(integrate(state, torch.zeros(3, 40, 10), coasting=True), constant_velocity(state, 40))


def test_a_probe_reading_latent_changes_needs_the_last_context_latent():
    torch.manual_seed(0)  # the MLP's initialisation
    g = torch.Generator().manual_seed(0)
    probe = PhysicsProbe(ProbeConfig(latent_dim=8, hidden=16, inputs="latent+change"))
    assert probe.increments.net[0].in_features == 16  # [z_k, z_k - z_{k-1}]
    state = make_state(2, v=(0.4, 0, 0))
    z = torch.randn(2, 5, 8, generator=g)
    assert torch.allclose(probe(z, state, torch.randn(2, 8, generator=g)), integrate(state, torch.zeros(2, 5, 10)))
    with pytest.raises(ValueError, match="z_last"):
        probe(z, state)
    torch.nn.init.normal_(probe.increments.net[-1].weight, generator=torch.Generator().manual_seed(0))
    z_last = torch.randn(2, 8, generator=g)
    first = probe(z[:, :1], state, z_last)  # the first step's change is taken from z_last
    # (the 5-step integration orthonormalises its attitude product once at the end: ~1e-7 apart)
    assert torch.allclose(probe(z, state, z_last)[:, :1], first, atol=1e-6)
    assert not torch.allclose(first, probe(z[:, :1], state, z_last + 1), atol=1e-6)
    with pytest.raises(ValueError, match="inputs"):
        ProbeConfig(kind="state", latent_dim=STATE_ACTION_DIM, inputs="latent+change")
    upstream = PhysicsProbe(ProbeConfig(latent_dim=8, hidden=16))  # reads z_k alone: z_last changes nothing
    torch.nn.init.normal_(upstream.increments.net[-1].weight, generator=torch.Generator().manual_seed(1))
    assert torch.equal(upstream(z, state), upstream(z, state, z_last))


def test_a_per_frame_probe_gives_each_frame_of_a_latent_step_its_own_increments():
    """substeps = s: the MLP's 10 s outputs of latent k are the increments of frames s(k-1)+1..sk,
    in time order, each integrated over dt; per_frame returns them as they are, while a probe with
    one increment per latent has the frames between its latents interpolated."""
    from orbitmodel.kinematics import interpolate_frames

    s, dt = 3, 0.04
    probe = PhysicsProbe(ProbeConfig(latent_dim=8, hidden=16, dt=dt, substeps=s, integrator="coasting"))
    assert probe.increments.net[-1].out_features == 10 * s
    state = make_state(2, v=(0.4, 0, 0), w=(0, 0, 0.2))
    z = torch.randn(2, 4, 8, generator=torch.Generator().manual_seed(0))
    assert torch.allclose(probe(z, state), constant_velocity(state, 4 * s, dt))  # untrained: coasting, frame by frame
    torch.nn.init.normal_(probe.increments.net[-1].weight, generator=torch.Generator().manual_seed(2))
    inc = probe.increments(z)  # (2, 12, 10)
    assert inc.shape == (2, 4 * s, 10)
    raw = probe.increments.net(z).reshape(2, 4, s, 10) * probe.increments.scale
    assert torch.equal(inc[:, s : 2 * s], raw[:, 1])  # latent 2 owns frames 4..6
    out = probe.per_frame(z, state, None, s)
    assert torch.equal(out, integrate(state, inc, dt, coasting=True)) and out.shape == (2, 12, 16)
    with pytest.raises(ValueError, match="predicts 3 frames per latent"):
        probe.per_frame(z, state, None, 5)
    knots = PhysicsProbe(ProbeConfig(latent_dim=8, hidden=16, dt=dt * s))
    torch.nn.init.normal_(knots.increments.net[-1].weight, generator=torch.Generator().manual_seed(3))
    assert torch.equal(knots.per_frame(z, state, None, s), interpolate_frames(state, knots(z, state), s))
    with pytest.raises(ValueError, match="substeps"):
        ProbeConfig(kind="state", latent_dim=STATE_ACTION_DIM, substeps=2)


def test_a_probe_reading_thrusts_takes_each_steps_action():
    """inputs "latent+change+thrust": the MLP reads [z_k, z_k - z_{k-1}] and a branch of its own a_k,
    the action that led to latent k; it is refused without them, and different thrusts give
    different increments."""
    probe = PhysicsProbe(ProbeConfig(latent_dim=8, hidden=16, inputs="latent+change+thrust", action_dim=16))
    assert probe.increments.net[0].in_features == 2 * 8 and probe.increments.thrust_net[0].in_features == 16
    torch.nn.init.normal_(probe.increments.net[-1].weight, generator=torch.Generator().manual_seed(0))
    torch.nn.init.normal_(probe.increments.thrust_net[-1].weight, generator=torch.Generator().manual_seed(2))
    g = torch.Generator().manual_seed(1)
    z, z_last, state = torch.randn(2, 3, 8, generator=g), torch.randn(2, 8, generator=g), make_state(2)
    thrusts = torch.rand(2, 3, 16, generator=g)
    with pytest.raises(ValueError, match="thrusts"):
        probe(z, state, z_last)
    with pytest.raises(ValueError, match="thrusts"):
        probe(z, state, z_last, thrusts[..., :8])
    out = probe(z, state, z_last, thrusts)
    assert out.shape == (2, 3, 16)
    # step k reads a_k, not later ones (the attitude product is orthonormalised once: ~1e-7 apart)
    assert torch.allclose(out[:, :2], probe(z[:, :2], state, z_last, thrusts[:, :2]), atol=1e-6)
    assert not torch.allclose(out, probe(z, state, z_last, thrusts.flip(-1)), atol=1e-6)
    with pytest.raises(ValueError, match="action_dim"):
        ProbeConfig(latent_dim=8, inputs="latent+change+thrust")


def test_a_probe_reading_thrusts_standardises_them_with_the_data_stats():
    """Thrusts enter the MLP as (a - mean) / std per thruster, tiled over the step's frames, so the
    stats set at training start move the output exactly as shifting the thrusts would."""
    probe = PhysicsProbe(ProbeConfig(latent_dim=4, hidden=8, inputs="latent+change+thrust", action_dim=16))
    torch.nn.init.normal_(probe.increments.thrust_net[-1].weight, generator=torch.Generator().manual_seed(0))
    g = torch.Generator().manual_seed(1)
    z, z_last, state = torch.randn(1, 2, 4, generator=g), torch.randn(1, 4, generator=g), make_state(1)
    thrusts = torch.rand(1, 2, 16, generator=g)
    mean, std = torch.full((8,), 0.1), torch.full((8,), 0.05)
    raw = probe(z, state, z_last, (thrusts - 0.1) / 0.05)
    probe.set_thrust_stats(mean, std)
    assert torch.equal(probe.thrust_mean, torch.full((16,), 0.1)) and "thrust_std" in probe.state_dict()
    assert torch.allclose(probe(z, state, z_last, thrusts), raw, atol=1e-6)
    assert "thrust_mean" not in PhysicsProbe(ProbeConfig(latent_dim=4, hidden=8)).state_dict()  # others load as before


def test_a_film_probe_starts_as_the_additive_one_and_learns_a_thrust_response_per_body():
    """inputs "...+thrust+film": untrained, it gives the additive probe's increments; trained on two
    bodies that the latent tells apart and whose thrust turns them opposite ways (the sign of the
    response flips with one latent feature), it fits what the additive branch cannot: one map from
    thrust to increment serves both bodies only on average."""
    from orbitmodel.probe.model import Increments

    def config(inputs):
        return ProbeConfig(latent_dim=4, hidden=32, inputs=inputs, action_dim=2)

    g = torch.Generator().manual_seed(0)
    additive, film = Increments(config("latent+change+thrust")), Increments(config("latent+change+thrust+film"))
    film.load_state_dict({**film.state_dict(), **additive.state_dict()})  # the same branches, FiLM at zero
    x, thrust = torch.randn(64, 1, 8, generator=g), torch.randn(64, 1, 2, generator=g)
    torch.nn.init.normal_(additive.thrust_net[-1].weight, generator=g)
    film.thrust_net[-1].weight.data.copy_(additive.thrust_net[-1].weight)
    assert torch.allclose(film(x, thrust), additive(x, thrust))

    def bodies(n):  # the latent says which body; its rates turn opposite ways under the same thrust
        body = torch.where(torch.rand(n, 1, 1, generator=g) < 0.5, -1.0, 1.0)
        x, thrust = torch.cat([body, torch.zeros(n, 1, 7)], dim=-1), torch.randn(n, 1, 2, generator=g)
        target = torch.zeros(n, 1, 10)
        target[..., 6:9] = body * thrust[..., :1]  # the body-rate increments
        return x, thrust, target

    train, held_out = bodies(512), bodies(512)

    def fitted(model) -> float:  # the MSE on held-out draws after fitting the training draws
        torch.manual_seed(0)
        opt = torch.optim.Adam(model.parameters(), lr=1e-2)
        for _ in range(300):
            opt.zero_grad()
            torch.nn.functional.mse_loss(model(*train[:2]), train[2]).backward()
            opt.step()
        with torch.no_grad():
            return float(torch.nn.functional.mse_loss(model(*held_out[:2]), held_out[2]))

    assert fitted(film) < 0.02 < 0.2 < fitted(Increments(config("latent+change+thrust")))


def test_a_thrust_only_probe_has_no_latent_input():
    """inputs "thrust": the thrust branch alone, so no weight sees a latent: random latents give
    the same states, other thrusts other states (every frame of a 2-frame step, as the flown head)."""
    config = ProbeConfig(latent_dim=8, hidden=16, inputs="thrust", action_dim=16, substeps=2, integrator="coasting")
    probe = PhysicsProbe(config)
    assert probe.increments.net is None and probe.increments.thrust_net[0].in_features == 16
    torch.nn.init.normal_(probe.increments.thrust_net[-1].weight, generator=torch.Generator().manual_seed(0))
    g = torch.Generator().manual_seed(1)
    state, thrusts = make_state(2, v=(0.4, 0, 0), w=(0, 0, 0.2)), torch.rand(2, 3, 16, generator=g)
    out = probe.per_frame(torch.randn(2, 3, 8, generator=g), state, torch.randn(2, 8, generator=g), 2, thrusts)
    assert out.shape == (2, 6, 16) and not torch.allclose(out, constant_velocity(state, 6), atol=1e-4)
    again = probe.per_frame(torch.randn(2, 3, 8, generator=g) * 10, state, None, 2, thrusts)
    assert torch.equal(out, again)
    assert not torch.allclose(out, probe.per_frame(torch.zeros(2, 3, 8), state, None, 2, thrusts.flip(-1)))
    with pytest.raises(ValueError, match="thrusts"):
        probe(torch.zeros(2, 3, 8), state)


def test_the_variants_change_only_what_they_name():
    """probe.variants: the paper's probe reads z_k with upstream's integrator and no increment loss;
    the thrust-only one reads thrusts alone; a candidate reads no thrusts; the rest is the recipe's."""
    from orbitmodel.cli.probe import VARIANT_NAMES
    from orbitmodel.config import get_preset
    from orbitmodel.probe.variants import CANDIDATES, VARIANTS, folder_name, variant_recipe

    flown = get_preset("cpu-step5").probe
    assert tuple(VARIANTS) == VARIANT_NAMES  # the CLI's choices, spelt there to keep its start light
    paper = variant_recipe(flown, "paper_probe")
    assert (paper.inputs, paper.integrator, paper.train.increment_weight) == ("latent", "upstream", 0.0)
    assert paper.per_frame and paper.train.loop == flown.train.loop and paper.train.weights == flown.train.weights
    only = variant_recipe(flown, "thrust_only")
    assert only.inputs == "thrust" and only == flown.with_changes(inputs="thrust")
    assert variant_recipe(flown, "thrust_probe") == flown and folder_name("thrust_probe") == "probe"
    for name in CANDIDATES:
        recipe = variant_recipe(flown, name)
        assert recipe.inputs in ("latent", "latent+change") and folder_name(name) == f"probe-{name}"
    assert variant_recipe(flown, "latent_probe-change-frames-inc") == flown.with_changes(inputs="latent+change")
    with pytest.raises(ValueError, match="choose one of"):
        variant_recipe(flown, "latent_probe")


def test_a_probe_loads_only_for_the_world_model_it_read(probed_run):
    """The fingerprint of the run's own model loads it; another is refused naming both; the model
    object itself (a common slip) is refused saying what to give."""
    from orbitmodel import PhysicsProbe, WorldModel
    from orbitmodel.runs import RunError

    model = WorldModel.from_pretrained(probed_run)
    assert PhysicsProbe.from_pretrained(probed_run, world_model=model.fingerprint) is not None
    with pytest.raises(
        RunError, match=r"was trained on another world model \(\w+\) than the deadbeef given: if .* was trained again"
    ):
        PhysicsProbe.from_pretrained(probed_run, world_model="deadbeef")
    with pytest.raises(ValueError, match=r"world_model is a WorldModel: give the world model's fingerprint"):
        PhysicsProbe.from_pretrained(probed_run, world_model=model)
