"""sample_reactions: batched, per-sample seeds, batch person order, causal end to end."""

from __future__ import annotations

import pytest
import torch
from reaction_builders import make_net, parts, standing_pair

from intermask.reaction.guidance import Guidance
from intermask.reaction.sampler import generate_reaction, sample_reactions

STOCHASTIC = Guidance(beta=0.05)


def _batch(lengths=(6, 4), actor=(1, 2)):
    motion = standing_pair(batch=len(lengths), frames=6, gap=0.6)
    motion[..., 66:] = 0.01 * torch.randn(
        motion[..., 66:].shape, generator=torch.Generator().manual_seed(0)
    )
    return {"motion": motion, "length": torch.tensor(lengths), "actor": torch.tensor(actor)}


def test_shapes_padding_and_person_order():
    batch = _batch()
    sample = sample_reactions(parts(make_net(causal=True)), batch, steps=2)
    assert sample.features.shape == (2, 6, 262) and sample.joints.shape == (2, 6, 2, 22, 3)
    assert sample.features[1, 4:].abs().max() == 0 and sample.joints[1, 4:].abs().max() == 0
    # the actor keeps its slot and its motion: person 1 acts in item 0, person 2 in item 1
    gt = batch["motion"][..., :66].reshape(2, 2, 6, 22, 3)
    torch.testing.assert_close(sample.joints[0, :, 0], gt[0, 0])
    torch.testing.assert_close(sample.joints[1, :4, 1], gt[1, 1, :4])
    torch.testing.assert_close(sample.joints[0, :, 1], sample.features[0, :, :66].reshape(6, 22, 3))


def test_without_annotation_person_one_acts():
    batch = _batch()
    del batch["actor"]
    sample = sample_reactions(parts(make_net(causal=True)), batch, steps=1)
    gt = batch["motion"][..., :66].reshape(2, 2, 6, 22, 3)
    torch.testing.assert_close(sample.joints[1, :4, 0], gt[1, 0, :4])


def test_seeds_are_per_sample():
    batch = _batch()
    net = parts(make_net(causal=True))
    pair = sample_reactions(net, batch, steps=2, guidance=STOCHASTIC, seeds=[5, 6]).features
    alone = {key: value[1:] for key, value in batch.items()}
    single = sample_reactions(net, alone, steps=2, guidance=STOCHASTIC, seeds=torch.tensor([6]))
    torch.testing.assert_close(single.features[0], pair[1])
    other = sample_reactions(net, alone, steps=2, guidance=STOCHASTIC, seeds=[7]).features
    assert (other[0] - pair[1]).abs().max() > 1e-6
    # without stochastic sampling the ODE from the action is deterministic
    plain = [sample_reactions(net, alone, steps=2, seeds=[s]).features for s in (1, 2)]
    torch.testing.assert_close(plain[0], plain[1])


def test_guided_online_sampling_stays_causal():
    net = parts(make_net(causal=True))
    actor = standing_pair(batch=1, frames=8, gap=0.4)[:, 0]
    mask = torch.ones(1, 8, dtype=torch.bool)
    out = generate_reaction(net, actor, mask, steps=3, guidance=Guidance(beta=0.05))
    changed = actor.clone()
    changed[:, 5:, :66] += 0.3
    out2 = generate_reaction(net, changed, mask, steps=3, guidance=Guidance(beta=0.05))
    torch.testing.assert_close(out2[:, :5], out[:, :5])
    assert (out2[:, 5:] - out[:, 5:]).abs().max() > 1e-4


def test_classifier_free_guidance_is_one_batched_call_per_step():
    inner = make_net(causal=True, text_dim=8)
    calls = []
    inner.register_forward_hook(lambda module, args, out: calls.append(args[0].shape[0]))
    actor = torch.randn(3, 5, 262)
    mask = torch.ones(3, 5, dtype=torch.bool)
    generate_reaction(parts(inner), actor, mask, text=torch.randn(3, 8), steps=4, cfg_scale=2.0)
    assert calls == [6, 6, 6, 6]


def test_errors():
    batch = _batch()
    net = parts(make_net(causal=True))
    with pytest.raises(
        ValueError, match=r"lengths must be \(B,\) frames in \[1, 6\], got \[0, 4\]"
    ):
        sample_reactions(net, {**batch, "length": torch.tensor([0, 4])})
    with pytest.raises(ValueError, match="got 1 seeds for 2 samples"):
        sample_reactions(net, batch, seeds=[1])
    with pytest.raises(TypeError, match="expected an ARFlowModule or ReactionParts, got dict"):
        sample_reactions({}, batch)
