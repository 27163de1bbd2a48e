"""The GAN's stride-1 max pool gives torch's MaxPool1d values and gradients bit for bit, ties included."""

import pytest
import torch
import torch.nn.functional as F

from ddfbench.models._stride1_pool import Stride1MaxPool1d
from ddfbench.models.gan_sdf import discriminator


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


def test_gan_pass_gradients_equal_torch_pools():
    """The bench's thesis pass through G and D (ddfbench.bench.gan_train): every parameter's gradient equals
    the same networks' with nn.MaxPool1d, so the bench times the same work both ways."""
    from ddfbench.bench.gan_train import training_pass

    grads = []
    for torch_pools in (False, True):
        run, nets = training_pass(32, torch_pools, "cpu")
        run()
        grads.append([p.grad.clone() for net in nets for p in net.parameters()])
    assert len(grads[0]) == len(grads[1]) > 0
    assert all(torch.equal(a, b) for a, b in zip(*grads))


def test_double_backward_equals_torch():
    """The R1 penalty (model.w_gp) differentiates D's input gradient: D's parameter gradients match torch's."""
    grads = []
    for torch_pools in (False, True):
        torch.manual_seed(0)
        d = discriminator(False)
        if torch_pools:
            d.pool = torch.nn.MaxPool1d(3, stride=1)
        real = torch.cat([torch.rand(48, 3) - 0.5, torch.randn(48, 1)], 1).requires_grad_()
        (grad,) = torch.autograd.grad(d(real).sum(), real, create_graph=True)
        grad.pow(2).sum(1).mean().backward()
        grads.append([p.grad for p in d.parameters() if p.grad is not None])  # not the head's bias
    assert len(grads[0]) == len(grads[1]) >= 7
    assert all(torch.equal(a, b) for a, b in zip(*grads))
