"""The GAN's stride-1 max pool gives torch's MaxPool1d values and gradients bit for bit, ties included."""

import pytest
import torch
import torch.nn.functional as F

from ddfbench.models._stride1_pool import Stride1MaxPool1d
from ddfbench.models.gan_sdf import discriminator, generator


@pytest.mark.parametrize("window", [2, 3, 5])
@pytest.mark.parametrize("decimals", [None, 0, 1])  # rounding makes ties within windows, and shared maxima
def test_values_and_gradients_equal_torch(window, decimals):
    g = torch.Generator().manual_seed(window)
    h = torch.randn(7, 4, 40, generator=g)
    if decimals is not None:
        h = h.round(decimals=decimals)
    grad_out = torch.randn(7, 4, 40 - window + 1, generator=g)
    ours_in, ref_in = h.clone().requires_grad_(), h.clone().requires_grad_()
    ours, ref = Stride1MaxPool1d(window)(ours_in), F.max_pool1d(ref_in, window, 1)
    ours.backward(grad_out)
    ref.backward(grad_out)
    assert torch.equal(ours, ref)
    assert torch.equal(ours_in.grad, ref_in.grad)
    if decimals == 0:  # the test means something only where windows tie
        assert (torch.eq(h[..., :-1], h[..., 1:])).any()


def test_plain_forward_without_autograd():
    h = torch.randn(2, 3, 10, requires_grad=True)
    with torch.no_grad():
        y = Stride1MaxPool1d(3)(h)
    assert y.grad_fn is None and torch.equal(y, F.max_pool1d(h.detach(), 3, 1))


def test_gan_step_gradients_equal_torch_pools():
    """One thesis loss through G and D: every parameter's gradient equals the same networks with nn.MaxPool1d."""
    torch.manual_seed(0)
    g, d = generator(), discriminator(False)
    g_ref, d_ref = generator(), discriminator(False)
    g_ref.load_state_dict(g.state_dict())
    d_ref.load_state_dict(d.state_dict())
    for net in (g_ref, d_ref):
        net.pool = torch.nn.MaxPool1d(3, stride=1)
    x, target = torch.rand(64, 3) - 0.5, torch.randn(64)

    def loss(gen, disc):
        pred = gen(x)
        return (pred - target).pow(2).mean() + torch.sigmoid(disc(torch.cat([x, pred[:, None]], 1))).mean()

    loss(g, d).backward()
    loss(g_ref, d_ref).backward()
    for (name, p), q in zip([*g.named_parameters(), *d.named_parameters()],
                            [*g_ref.parameters(), *d_ref.parameters()]):
        assert torch.equal(p.grad, q.grad), name


def test_bench_passes_compute_the_same_gradients():
    """The bench's two ways (ddfbench.bench.gan_train) differ only in the pools: the same weights and gradients."""
    from ddfbench.bench.gan_train import training_pass

    grads = []
    for torch_pools in (False, True):
        run, nets = training_pass(32, torch_pools, "cpu")
        run()
        grads.append([p.grad.clone() for net in nets for p in net.parameters()])
    assert len(grads[0]) == len(grads[1]) > 0
    assert all(torch.equal(a, b) for a, b in zip(*grads))
