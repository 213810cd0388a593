import torch

from grip.kinematics.model import STAGE_DIMS, STAGES, FrameStep, KinematicsNet, KinematicsNetConfig


def _net(seed=0):
    torch.manual_seed(seed)
    return KinematicsNet(KinematicsNetConfig(n_inputs=70, hidden=32, layers=2, init_hidden=16))


def _first(b):
    g = torch.Generator().manual_seed(1)
    return {k: torch.randn(b, d, generator=g) for k, d in STAGE_DIMS.items()}


def test_shapes():
    net = _net()
    x = torch.randn(3, 40, 70)
    out, state = net(x, net.initial_state(_first(3)))
    assert {k: tuple(v.shape) for k, v in out.items()} == {
        k: (3, 40, d) for k, d in STAGE_DIMS.items()
    }
    assert state["fa"][0].shape == (2, 3, 32)


def test_streaming_equals_offline():
    net = _net().eval()
    x = torch.randn(2, 25, 70)
    with torch.no_grad():
        full, _ = net(x, net.initial_state(_first(2)))
        state = net.initial_state(_first(2))
        steps = []
        for t in range(25):
            y, state = net(x[:, t : t + 1], state)
            steps.append(y)
    for k in full:
        torch.testing.assert_close(torch.cat([s[k] for s in steps], 1), full[k], atol=1e-5,
                                   rtol=1e-5)  # fmt: skip


def test_frame_step_equals_the_network_frame_by_frame():
    """The streaming path (cells called directly) gives forward's outputs and states."""
    net = _net().eval()
    x = torch.randn(3, 25, 70)
    step = FrameStep(net)
    with torch.inference_mode():
        full, end = net(x, net.initial_state(_first(3)))
        flat = step.flat_state(net.initial_state(_first(3)))
        rows = torch.stack([step(x[:, t], flat) for t in range(25)], 1)
    torch.testing.assert_close(rows, torch.cat([full[k] for k in STAGES], -1), atol=1e-5,
                               rtol=1e-5)  # fmt: skip
    for k in STAGES:
        for got, want in zip(step.state(flat)[k], end[k], strict=True):
            torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)


def test_one_optimizer_step_lowers_the_loss():
    net = _net()
    x = torch.randn(4, 30, 70)
    target = {k: torch.randn(4, 30, d) for k, d in STAGE_DIMS.items()}
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)

    def loss():
        out, _ = net(x, net.initial_state(_first(4)))
        return sum(((out[k] - target[k]) ** 2).mean() for k in out)

    before = loss()
    opt.zero_grad()
    before.backward()
    opt.step()
    assert loss().item() < before.item()


def test_initial_state_depends_on_the_first_frame():
    net = _net().eval()
    a = net.initial_state(_first(1))
    other = {k: v + 1.0 for k, v in _first(1).items()}
    b = net.initial_state(other)
    assert not torch.allclose(a["lp"][0], b["lp"][0])


def test_stage_wise_training_leaves_earlier_stages_untouched():
    cfg = KinematicsNetConfig(n_inputs=7, hidden=8, layers=1, init_hidden=4)
    net = KinematicsNet(cfg)
    x = torch.randn(2, 5, 7)
    first = {k: torch.zeros(2, s.head.out_features) for k, s in net.stages.items()}
    out, _ = net(x, net.initial_state(first), only="fa")
    out["fa"].pow(2).mean().backward()
    for name in ("lp", "fp"):
        assert all(p.grad is None for p in net.stages[name].lstm.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0
               for p in net.stages["fa"].parameters())  # fmt: skip
    assert "lv" not in out
