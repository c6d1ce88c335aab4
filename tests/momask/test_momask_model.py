"""MoMask networks: the residual input sum, the weight tie, padding, the null condition."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from intermask.momask.model import MaskedTransformer, ResidualTransformer, sentence_features
from tests.momask.momask_tiny import CODES, make_mask_net, make_residual_net


def _residual_tokens(batch: int, layers: int, steps: int, lengths: list[int], seed: int = 0):
    generator = torch.Generator().manual_seed(seed)
    tokens = torch.randint(0, CODES, (batch, layers, steps), generator=generator)
    for row, length in enumerate(lengths):
        tokens[row, :, length:] = -1
    return tokens


def _text(batch: int, seed: int = 1) -> torch.Tensor:
    return torch.randn(batch, 64, generator=torch.Generator().manual_seed(seed))


def test_every_shared_table_is_one_parameter_for_input_and_output():
    net = make_residual_net(num_quantizers=6)
    for layer in range(1, 5):  # layers 1..Q-2 are embedded and predicted
        assert net.output_table(layer) is net.input_table(layer)
        assert net.output_table(layer) is net.tables[layer]
        assert isinstance(net.tables[layer], nn.Parameter)
    assert net.input_table(0) is net.tables[0]  # input only
    assert net.output_table(5) is net.tables[5]  # output only
    assert len(net.tables) == 6 and net.head_tables is None
    assert len({id(p) for p in net.parameters()}) == len(list(net.parameters()))


def test_the_tied_table_gets_gradient_from_both_roles():
    net = make_residual_net(num_quantizers=3).eval()
    tokens = _residual_tokens(2, 3, 6, [6, 6])
    lengths = torch.tensor([6, 6])
    # predicting layer 1 from layer 0 uses table 1 as output only
    net(tokens, _text(2), lengths, layer=1).sum().backward()
    assert net.tables[0].grad.abs().sum() > 0 and net.tables[1].grad.abs().sum() > 0
    assert net.tables[2].grad is None or net.tables[2].grad.abs().sum() == 0
    net.zero_grad()
    # predicting layer 2 from layers 0 and 1 uses table 1 as input, table 2 as output
    logits = net(tokens, _text(2), lengths, layer=2)
    logits.sum().backward()
    assert net.tables[1].grad.abs().sum() > 0 and net.tables[2].grad.abs().sum() > 0


def test_unshared_heads_have_their_own_tables():
    net = make_residual_net(num_quantizers=4, share_weights=False)
    assert len(net.tables) == 3 and len(net.head_tables) == 3
    for layer in (1, 2):
        assert net.output_table(layer) is not net.input_table(layer)
        assert net.output_table(layer) is net.head_tables[layer - 1]


def test_residual_input_is_the_sum_of_the_lower_layers_embeddings():
    net = make_residual_net(num_quantizers=4)
    lengths = [5, 3]
    tokens = _residual_tokens(2, 4, 5, lengths)
    layer = torch.tensor([3, 2])
    history = net.history(tokens, layer, torch.tensor(lengths))
    assert history.shape == (2, 5, 16)
    for b in range(2):
        for t in range(5):
            expected = torch.zeros(16)
            if t < lengths[b]:
                for i in range(int(layer[b])):
                    expected = expected + net.tables[i][tokens[b, i, t]]
            torch.testing.assert_close(history[b, t], expected)


def test_residual_logits_ignore_the_layers_at_and_above_the_predicted_one():
    net = make_residual_net(num_quantizers=4).eval()
    tokens = _residual_tokens(2, 4, 6, [6, 4])
    other = tokens.clone()
    other[:, 2:] = _residual_tokens(2, 2, 6, [6, 4], seed=9)
    lengths, text = torch.tensor([6, 4]), _text(2)
    with torch.no_grad():
        first = net(tokens, text, lengths, layer=2)
        second = net(other, text, lengths, layer=2)
        third = net(tokens[:, :2], text, lengths, layer=torch.tensor([2, 2]))
    torch.testing.assert_close(first, second)
    torch.testing.assert_close(first, third)
    assert first.shape == (2, 6, CODES)


def test_logits_of_the_layer_are_dot_products_with_its_table():
    net = make_residual_net(num_quantizers=3).eval()
    tokens, lengths, text = _residual_tokens(1, 3, 4, [4]), torch.tensor([4]), _text(1)
    with torch.no_grad():
        history = net.history(tokens, 2, lengths)
        prefix = net.layer_embedding(torch.tensor([1]))[:, None]
        hidden = net.head(net.backbone(history, text, lengths, None, prefix))
        expected = hidden @ net.tables[2].T + net.head_bias[1]
        torch.testing.assert_close(net(tokens, text, lengths, layer=2), expected)


def test_masked_logits_inside_a_clip_do_not_depend_on_its_padding():
    net = make_mask_net().eval()
    generator = torch.Generator().manual_seed(0)
    tokens = torch.randint(0, CODES + 1, (2, 8), generator=generator)  # codes and [MASK]
    lengths = torch.tensor([8, 5])
    changed = tokens.clone()
    changed[1, 5:] = torch.tensor([-1, 3, CODES + 1])  # -1, a code, [PAD]: all read as [PAD]
    with torch.no_grad():
        first = net(tokens, _text(2), lengths)
        second = net(changed, _text(2), lengths)
    assert first.shape == (2, 8, CODES)
    torch.testing.assert_close(first[1, :5], second[1, :5])
    torch.testing.assert_close(first[0], second[0])


def test_a_dropped_condition_is_the_zero_feature_whatever_the_caption():
    net = make_mask_net().eval()
    tokens, lengths = torch.full((2, 6), CODES), torch.tensor([6, 6])  # all [MASK]
    drop = torch.tensor([True, False])
    with torch.no_grad():
        dropped = net(tokens, _text(2, seed=1), lengths, drop)
        other = net(tokens, _text(2, seed=2), lengths, drop)
        zero = net(tokens, torch.zeros(2, 64), lengths)
        kept = net(tokens, _text(2, seed=1), lengths)
    torch.testing.assert_close(dropped[0], other[0])
    torch.testing.assert_close(dropped[0], zero[0])
    torch.testing.assert_close(dropped[1], kept[1])
    assert not torch.allclose(dropped[1], other[1])


def test_sentence_features_take_the_end_of_text_row():
    features = torch.arange(2 * 5 * 3, dtype=torch.float32).reshape(2, 5, 3)
    picked = sentence_features((features, torch.tensor([4, 1])))
    assert torch.equal(picked, torch.stack([features[0, 4], features[1, 1]]))


def test_paper_sizes_are_the_defaults():
    net = MaskedTransformer()
    assert net.codebook_size == 512 and net.text_dim == 512
    assert net.token_embedding.weight.shape == (514, 512)  # codes, [MASK], [PAD]
    assert len(net.backbone.encoder.layers) == 6
    assert net.backbone.encoder.layers[0].self_attn.num_heads == 6
    assert net.backbone.encoder.layers[0].linear1.weight.shape == (1024, 384)
    residual = ResidualTransformer()
    assert residual.num_quantizers == 6 and len(residual.tables) == 6
    assert residual.layer_embedding.weight.shape == (5, 384)


def test_errors_name_the_problem():
    net, residual = make_mask_net(), make_residual_net(num_quantizers=3)
    lengths, text = torch.tensor([4]), _text(1)
    with pytest.raises(ValueError, match=r"tokens must be \(B, T'\), got \(1, 1, 4\)"):
        net(torch.zeros(1, 1, 4, dtype=torch.long), text, lengths)
    with pytest.raises(ValueError, match=r"must lie in \[-1, 17\], got values in \[0, 18\]"):
        net(torch.tensor([[0, 18, 1, 1]]), text, lengths)
    with pytest.raises(ValueError, match=r"text must be \(B, D_text\) = \(1, 64\)"):
        net(torch.zeros(1, 4, dtype=torch.long), torch.zeros(1, 32), lengths)
    tokens = _residual_tokens(1, 3, 4, [4])
    with pytest.raises(ValueError, match=r"layer must lie in \[1, 2\], got \[3\]"):
        residual(tokens, text, lengths, layer=3)
    with pytest.raises(ValueError, match="needs the codes of the layers below it, tokens hold 1"):
        residual(tokens[:, :1], text, lengths, layer=2)
    broken = tokens.clone()
    broken[0, 0, 1] = -1
    with pytest.raises(ValueError, match="must be codes inside each clip's length, got -1"):
        residual(broken, text, lengths, layer=1)
    with pytest.raises(ValueError, match=r"input layers are 0..1, got 2"):
        residual.input_table(2)
    with pytest.raises(ValueError, match=r"predicted layers are 1..2, got 0"):
        residual.output_table(0)
    with pytest.raises(ValueError, match="num_quantizers must be >= 2"):
        ResidualTransformer(num_quantizers=1)
    with pytest.raises(ValueError, match=r"eot_index \(B,\)"):
        sentence_features((torch.zeros(2, 5, 3), torch.zeros(3, dtype=torch.long)))
