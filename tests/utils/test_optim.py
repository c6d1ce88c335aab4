"""Muon: the orthogonalised update of hidden matrices, AdamW for the rest, and its groups."""

from __future__ import annotations

from functools import partial

import pytest
import torch
from torch import nn

from intermask.utils.optim import Muon, builds_muon, muon_groups, orthogonalize


def test_orthogonalize_brings_every_singular_value_near_one_in_both_orientations() -> None:
    generator = torch.Generator().manual_seed(0)
    for shape in ((48, 16), (16, 48), (3, 32, 96)):
        # a well-conditioned and an ill-conditioned spectrum: singular values 1 ... 1/50
        u, _, vh = torch.linalg.svd(torch.randn(*shape, generator=generator), full_matrices=False)
        spectrum = torch.logspace(0, -1.7, u.shape[-1])
        out = orthogonalize(u * spectrum @ vh)
        assert out.shape == torch.Size(shape) and out.dtype == torch.float32
        singular = torch.linalg.svdvals(out)
        assert singular.min() > 0.6 and singular.max() < 1.25, singular
        # the directions are kept: out is U f(S) V^T with the input's U and V
        core = u.mT @ out @ vh.mT
        off = core - torch.diag_embed(torch.diagonal(core, dim1=-2, dim2=-1))
        assert off.abs().max() < 1e-4
    with pytest.raises(ValueError, match=r"needs \(\.\.\., m, n\) matrices, got \(5,\)"):
        orthogonalize(torch.ones(5))


def test_orthogonalize_of_a_stack_is_each_matrix_orthogonalised_alone() -> None:
    stack = torch.randn(4, 12, 20, generator=torch.Generator().manual_seed(1))
    batched = orthogonalize(stack)
    for matrix, expected in zip(stack, batched, strict=True):
        torch.testing.assert_close(orthogonalize(matrix), expected, atol=1e-5, rtol=1e-5)


def test_adamw_groups_step_like_torch_adamw() -> None:
    torch.manual_seed(0)
    reference = nn.Parameter(torch.randn(6, 4))
    mine = nn.Parameter(reference.detach().clone())
    bias_ref = nn.Parameter(torch.randn(4))
    bias_mine = nn.Parameter(bias_ref.detach().clone())
    settings = {"lr": 1e-2, "betas": (0.9, 0.99), "weight_decay": 1e-2, "eps": 1e-8}
    torch_adamw = torch.optim.AdamW([reference, bias_ref], **settings)
    muon = Muon([mine, bias_mine], **settings)  # plain parameters: all AdamW
    for _ in range(25):
        grads = torch.randn(6, 4), torch.randn(4)
        for p, q, g in zip((reference, bias_ref), (mine, bias_mine), grads, strict=True):
            p.grad, q.grad = g.clone(), g.clone()
        torch_adamw.step()
        muon.step()
    # torch raises the betas to a float32 step count, this module to a Python int: the bias
    # corrections may differ in the last bit
    torch.testing.assert_close(mine, reference, rtol=1e-6, atol=1e-7)
    torch.testing.assert_close(bias_mine, bias_ref, rtol=1e-6, atol=1e-7)


def test_a_muon_step_moves_a_matrix_by_its_orthogonalised_nesterov_momentum() -> None:
    weight = nn.Parameter(torch.zeros(8, 32))
    optimizer = Muon([{"params": [weight], "muon": True}], lr=0.1, momentum=0.5)
    first, second = torch.randn(2, 8, 32, generator=torch.Generator().manual_seed(2))
    weight.grad = first
    optimizer.step()
    scale = 0.1 * 0.2 * 32**0.5  # lr x the RMS match of the 8 x 32 shape
    # momentum buffer m1 = 0.5 g1; Nesterov update g1 + 0.5 (m1 - g1) = 0.75 g1
    torch.testing.assert_close(weight.detach(), -scale * orthogonalize(0.75 * first))
    before = weight.detach().clone()
    weight.grad = second
    optimizer.step()
    buffer = 0.5 * (0.5 * first) + 0.5 * second
    expected = before - scale * orthogonalize(second + 0.5 * (buffer - second))
    torch.testing.assert_close(weight.detach(), expected)
    # with the RMS match, the update's RMS is 0.2 x lr x sqrt(32 / 8) x ~1 per singular value
    update_rms = (weight.detach() - before).pow(2).mean().sqrt()
    assert 0.2 * 0.1 * 0.6 < update_rms < 0.2 * 0.1 * 1.25


def test_weight_decay_is_decoupled_for_both_rules() -> None:
    matrix, vector = nn.Parameter(torch.ones(4, 4)), nn.Parameter(torch.ones(4))
    optimizer = Muon(
        [{"params": [matrix], "muon": True}, {"params": [vector]}], lr=0.0, weight_decay=0.5
    )
    matrix.grad, vector.grad = torch.ones(4, 4), torch.ones(4)
    optimizer.step()  # lr 0: nothing moves, decay included (it is lr x weight_decay)
    assert torch.equal(matrix, torch.ones(4, 4)) and torch.equal(vector, torch.ones(4))
    optimizer.param_groups[0]["lr"] = optimizer.param_groups[1]["lr"] = 0.1
    matrix.grad = vector.grad = None  # no gradient: no step, no decay
    optimizer.step()
    assert torch.equal(matrix, torch.ones(4, 4)) and torch.equal(vector, torch.ones(4))


def test_muon_groups_refuse_what_is_not_a_matrix_and_settings_out_of_range() -> None:
    with pytest.raises(ValueError, match=r"takes weight matrices .* got shapes \[\(4,\)\]"):
        Muon([{"params": [nn.Parameter(torch.ones(4))], "muon": True}], lr=0.1)
    with pytest.raises(ValueError, match="momentum in \\[0, 1\\) .* momentum=1.0"):
        Muon([nn.Parameter(torch.ones(2, 2))], lr=0.1, momentum=1.0)
    with pytest.raises(ValueError, match="ns_steps >= 1.*ns_steps=0"):
        Muon([nn.Parameter(torch.ones(2, 2))], lr=0.1, ns_steps=0)


def test_muon_groups_split_matrices_from_the_rest_and_keep_what_is_named_on_adamw() -> None:
    net = nn.Sequential(nn.Embedding(10, 8), nn.Linear(8, 8), nn.LayerNorm(8), nn.Linear(8, 10))
    net[2].requires_grad_(False)
    matrices, others = muon_groups(net.parameters(), adamw=[net[0].weight, *net[3].parameters()])
    assert matrices["muon"] and not others["muon"]
    assert [id(p) for p in matrices["params"]] == [id(net[1].weight)]
    assert {id(p) for p in others["params"]} == {
        id(p) for p in (net[0].weight, net[1].bias, net[3].weight, net[3].bias)
    }  # the frozen LayerNorm is in neither


def test_builds_muon_reads_classes_and_hydra_partials() -> None:
    assert builds_muon(Muon) and builds_muon(partial(Muon, lr=1e-3))
    assert not builds_muon(torch.optim.AdamW) and not builds_muon(partial(torch.optim.AdamW))
    assert not builds_muon(lambda params: torch.optim.SGD(params, lr=1.0))


def test_a_convolution_kernel_steps_as_the_out_by_fan_in_matrix_it_applies() -> None:
    conv = nn.Conv2d(3, 4, kernel_size=2)
    matrices, others = muon_groups(conv.parameters())
    assert [id(p) for p in matrices["params"]] == [id(conv.weight)]
    assert [id(p) for p in others["params"]] == [id(conv.bias)]
    before = conv.weight.detach().clone()
    optimizer = Muon([matrices], lr=0.1, momentum=0.0)
    grad = torch.randn(4, 3, 2, 2, generator=torch.Generator().manual_seed(5))
    conv.weight.grad = grad
    optimizer.step()
    scale = 0.1 * 0.2 * 12**0.5  # the 4 x 12 matrix's RMS match
    expected = before - scale * orthogonalize(grad.reshape(4, 12)).reshape(4, 3, 2, 2)
    torch.testing.assert_close(conv.weight.detach(), expected)
