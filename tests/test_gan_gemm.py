"""The GAN generator's matrix-product evaluation (ddfbench.models._gan_gemm) is the Conv1d network's function."""

import pytest
import torch

from ddfbench.models import _gan_gemm as gan_gemm
from ddfbench.models import load_family
from ddfbench.models.gan_sdf import discriminator, generator


def _spread_generator(seed: int) -> torch.nn.Module:
    """A generator with weights large enough that the pools and activations pick different winners per point."""
    torch.manual_seed(seed)
    net = generator().eval()
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(3.0)
    return net


def _no_forward(net: torch.nn.Module) -> None:
    def refuse(*_args, **_kwargs):
        raise AssertionError("the Conv1d module was called")
    net.forward = refuse


@pytest.mark.parametrize("chunk", [1, 7, 16, 500])
def test_matrix_products_give_the_conv1d_networks_values(chunk):
    net = _spread_generator(0)
    points = (torch.rand(203, 3, generator=torch.Generator().manual_seed(1)) - 0.5) * 1.2
    with torch.no_grad():
        expected = net(points)
    _no_forward(net)  # the values below come from the packed matrices alone
    gemm = gan_gemm.GemmGenerator()
    got = gemm(net, points, chunk)
    assert got.shape == (203,)
    assert expected.std() > 0.1  # the points are told apart: a constant answer would fail below
    torch.testing.assert_close(got, expected, rtol=1e-5, atol=1e-5)
    first = got.clone()
    torch.testing.assert_close(gemm(net, points[:37], chunk), expected[:37], rtol=1e-5, atol=1e-5)
    assert torch.equal(got, first)  # a later call writes its own output, not one handed out before
    assert gemm(net, points[:0], chunk).shape == (0,)


def test_the_family_field_follows_every_change_of_the_weights_and_keeps_a_graph_when_asked():
    rep = load_family("gan_sdf")({"eval_batch": 5, "target_scale": 4.0})
    rep.net.load_state_dict(_spread_generator(2).state_dict())
    points = torch.rand(40, 3) - 0.5
    forward = rep.net.forward
    with torch.no_grad():
        reference = rep.net(points) / 4.0
    _no_forward(rep.net)  # with autograd off the family must not go through the Conv1d module
    with torch.no_grad():
        before = rep.field(points)
        torch.testing.assert_close(before, reference, rtol=1e-5, atol=1e-6)
        rep.net.head.bias.add_(1.0)  # an in-place change, as an optimizer step makes
        torch.testing.assert_close(rep.field(points), before + 0.25, rtol=1e-5, atol=1e-5)
    rep.net.head.bias.data.sub_(1.0)  # through .data, which a version counter does not see
    with torch.inference_mode():
        torch.testing.assert_close(rep.field(points), before, rtol=1e-5, atol=1e-6)
    with torch.no_grad():  # buffers first made under inference mode are still writable here
        torch.testing.assert_close(rep.field(points), before, rtol=1e-5, atol=1e-6)
    # weights the packing copies (not the biases it reads live): in place, then through .data
    for change in (lambda: rep.net.conv2.weight.mul_(1.5), lambda: rep.net.lift.weight.data.mul_(0.5)):
        with torch.no_grad():
            change()
            changed = _spread_generator(2)
            changed.load_state_dict(rep.net.state_dict())
            torch.testing.assert_close(rep.field(points), changed(points) / 4.0, rtol=1e-5, atol=1e-6)
    rep.net.forward = forward
    x = points.clone().requires_grad_(True)
    value = rep.field(x)
    (grad,) = torch.autograd.grad(value.sum(), x)
    assert grad.abs().sum() > 0
    with torch.no_grad():
        torch.testing.assert_close(value.detach(), rep.field(points), rtol=1e-5, atol=1e-6)


def test_only_the_generators_stack_is_packed_and_a_chunk_holds_a_point():
    points = torch.zeros(3, 3)
    with pytest.raises(ValueError, match="chunk 0"):
        gan_gemm.GemmGenerator()(generator(), points, 0)
    with pytest.raises(ValueError, match="Tanh then ReLU"):
        gan_gemm.GemmGenerator()(discriminator(spectral=False), torch.zeros(3, 4), 2)
    padded = generator()
    padded.conv2.padding = (1,)
    with pytest.raises(ValueError, match="unpadded"):
        gan_gemm.GemmGenerator()(padded, points, 2)
