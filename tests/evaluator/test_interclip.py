"""InterCLIP: layout of the motion input, padding / order invariances, text side, errors."""

from __future__ import annotations

import pytest
import torch
from evaluator_builders import CAPTIONS, interhuman_batch, tiny_interclip

from intermask.evaluator import InterCLIP
from intermask.text import TINY_MODEL_NAME


def test_embeddings_have_norm_latent_scale(interclip):
    motion, lengths = interhuman_batch()
    with torch.no_grad():
        interclip.latent_scale.fill_(2.5)
        m = interclip.encode_motion(motion, lengths)
        t = interclip.encode_text(CAPTIONS)
    assert m.shape == (3, 512) and t.shape == (3, 512)
    assert torch.allclose(m.norm(dim=-1), torch.full((3,), 2.5), atol=1e-5)
    assert torch.allclose(t.norm(dim=-1), torch.full((3,), 2.5), atol=1e-5)
    assert float(interclip.logit_scale().detach()) == pytest.approx(6.25)


def test_padding_content_and_padded_length_do_not_matter(interclip):
    motion, lengths = interhuman_batch()
    noisy = motion.clone()
    for row, length in enumerate(lengths.tolist()):
        noisy[row, :, length:] = 1e3  # de-normalized padding is the mean, not zero
    longer = torch.cat([motion, torch.randn(3, 2, 11, 262)], dim=2)
    with torch.no_grad():
        reference = interclip.encode_motion(motion, lengths)
        assert torch.allclose(interclip.encode_motion(noisy, lengths), reference, atol=1e-5)
        assert torch.allclose(interclip.encode_motion(longer, lengths), reference, atol=1e-5)


def test_rows_are_independent_and_stay_in_input_order(interclip):
    """The reference sorts by length and re-indexes the texts; per-row encoding makes it moot."""
    motion, lengths = interhuman_batch(batch=5)
    with torch.no_grad():
        batched = interclip.encode_motion(motion, lengths)
        order = torch.argsort(lengths, descending=True)  # the reference's align_idx
        sorted_rows = interclip.encode_motion(motion[order], lengths[order])
        single = torch.cat(
            [interclip.encode_motion(motion[i : i + 1], lengths[i : i + 1]) for i in range(5)]
        )
    assert torch.allclose(sorted_rows, batched[order], atol=1e-5)
    assert torch.allclose(single, batched, atol=1e-5)


def test_foot_contacts_are_ignored_and_persons_are_concatenated(interclip):
    motion, lengths = interhuman_batch()
    changed = motion.clone()
    changed[..., -4:] = torch.randn_like(changed[..., -4:])
    swapped = motion.flip(1)
    with torch.no_grad():
        reference = interclip.encode_motion(motion, lengths)
        assert torch.allclose(interclip.encode_motion(changed, lengths), reference, atol=1e-5)
        assert not torch.allclose(interclip.encode_motion(swapped, lengths), reference, atol=1e-3)
    # the first Linear sees [P1 258 | P2 258] per frame
    frames = []
    interclip.motion_encoder.embed_motion.register_forward_hook(lambda m, i, o: frames.append(i[0]))
    with torch.no_grad():
        interclip.encode_motion(motion, lengths)
    assert frames[0].shape == (3, 20, 516)
    assert torch.equal(frames[0][1, :, :258], motion[1, 0, :, :258])
    assert torch.equal(frames[0][1, :, 258:], motion[1, 1, :, :258])


def test_text_pools_the_end_of_text_token_and_embeddings_are_frozen(interclip):
    ids = interclip.tokenizer(CAPTIONS)
    captured = []
    interclip.text_ln.register_forward_hook(lambda m, i, o: captured.append(o))
    with torch.no_grad():
        out = interclip.encode_text(CAPTIONS)
        expected = interclip.out(captured[0][torch.arange(3), ids.argmax(-1)])
    scale = interclip.latent_scale
    assert torch.allclose(out, torch.nn.functional.normalize(expected, dim=-1) * scale, atol=1e-6)
    assert not interclip.token_embedding.weight.requires_grad
    assert not interclip.positional_embedding.requires_grad
    trainable = {n for n, p in interclip.named_parameters() if p.requires_grad}
    assert "latent_scale" in trainable and "motion_encoder.query_token" in trainable


def test_embeddings_are_copied_from_the_frozen_clip_tower(tiny_text_encoder):
    net = InterCLIP(
        text_encoder=tiny_text_encoder,
        width=16,
        layers=1,
        heads=2,
        ff=16,
        text_layers=1,
        text_heads=2,
        text_ff=16,
    )
    assert torch.equal(net.token_embedding.weight, tiny_text_encoder.token_embedding.weight)
    assert torch.equal(net.positional_embedding, tiny_text_encoder.positional_embedding)
    assert net.clip_model_name == TINY_MODEL_NAME
    assert not any(name.startswith("transformer.") for name, _ in net.named_parameters())


def test_released_module_names():
    keys = set(tiny_interclip().state_dict())
    for key in [
        "latent_scale",
        "token_embedding.weight",
        "positional_embedding",
        "textTransEncoder.layers.0.self_attn.in_proj_weight",
        "textTransEncoder.layers.0.linear1.weight",
        "text_ln.weight",
        "out.weight",
        "motion_encoder.query_token",
        "motion_encoder.embed_motion.weight",
        "motion_encoder.sequence_pos_encoder.pe",
        "motion_encoder.transformer.layers.1.norm2.bias",
        "motion_encoder.out_ln.weight",
        "motion_encoder.out.weight",
    ]:
        assert key in keys, key
    pe = tiny_interclip().motion_encoder.sequence_pos_encoder.pe
    assert pe.shape == (2000, 32)
    assert torch.allclose(
        pe[3, 0::2],
        torch.sin(3 * torch.exp(torch.arange(0, 32, 2) * (-torch.log(torch.tensor(1e4)) / 32))),
    )


def test_errors_name_the_problem(interclip):
    motion, lengths = interhuman_batch()
    with pytest.raises(
        ValueError, match=r"expects de-normalized motion \(B, 2, T, 262\), got \(3, 20, 524\)"
    ):
        interclip.encode_motion(motion.reshape(3, 20, 524), lengths)
    with pytest.raises(ValueError, match=r"lengths must lie in \[1, 20\].*max 21"):
        interclip.encode_motion(motion, lengths + 1)
    with pytest.raises(ValueError, match="lengths has 2 entries for a batch of 3"):
        interclip.encode_motion(motion, lengths[:2])
    with pytest.raises(TypeError, match="a single string"):
        interclip.encode_text("a person waves")
    with pytest.raises(ValueError, match="give exactly one of text_encoder"):
        InterCLIP()
    with pytest.raises(ValueError, match="motion_dim must be 2 x"):
        InterCLIP(clip_model_name=TINY_MODEL_NAME, motion_dim=524)
