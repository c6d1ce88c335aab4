"""Who acts: the dataset's annotation, else person 1."""

from __future__ import annotations

import pytest
import torch

from intermask.reaction.roles import actor_index, place_reaction, split_roles


def _motion(batch: int = 3) -> torch.Tensor:
    motion = torch.zeros(batch, 2, 4, 5)
    motion[:, 1] = 1.0  # person 2 is all ones
    return motion


def test_annotation_names_the_actor_else_person_one():
    motion = _motion()
    assert actor_index({"motion": motion}).tolist() == [0, 0, 0]
    assert actor_index({"motion": motion, "actor": torch.tensor([1, 2, 2])}).tolist() == [0, 1, 1]
    assert actor_index({"motion": motion, "actor": [2, 1, 2]}).tolist() == [1, 0, 1]


def test_split_and_place_round_trip():
    motion = _motion()
    actor = torch.tensor([0, 1, 1])
    roles = split_roles(motion, actor)
    assert roles.actor[:, 0, 0].tolist() == [0.0, 1.0, 1.0]
    assert roles.reactor[:, 0, 0].tolist() == [1.0, 0.0, 0.0]
    assert torch.equal(place_reaction(motion, roles.reactor, actor), motion)
    replaced = place_reaction(motion, torch.full_like(roles.reactor, 7.0), actor)
    assert replaced[0, 1, 0, 0] == 7 and replaced[1, 0, 0, 0] == 7 and replaced[1, 1, 0, 0] == 1


def test_bad_annotations_are_reported():
    motion = _motion()
    with pytest.raises(
        ValueError, match=r"must name person 1 or 2, got \[0, 3\] at items \[0, 2\]"
    ):
        actor_index({"motion": motion, "actor": torch.tensor([0, 1, 3])})
    with pytest.raises(ValueError, match="has 2 entries for 3 items"):
        actor_index({"motion": motion, "actor": torch.tensor([1, 2])})
    with pytest.raises(ValueError, match=r"motion must be \(B, 2, T, \*F\), got \(3, 4, 5\)"):
        split_roles(motion[:, 0], torch.zeros(3, dtype=torch.long))
    with pytest.raises(ValueError, match="like one person of motion"):
        place_reaction(motion, motion[:, 0, :2], torch.zeros(3, dtype=torch.long))


def test_the_synthetic_items_carry_the_actor(synthetic_interhuman_root, synthetic_interx_root):
    from intermask.data.common import read_interaction_meta
    from intermask.data.interhuman import InterHumanDataset
    from intermask.data.interx import InterXDataset

    for root, cls in (
        (synthetic_interhuman_root, InterHumanDataset),
        (synthetic_interx_root, InterXDataset),
    ):
        dataset = cls(root=root, split="train", mode="interaction", swap_persons=True)
        meta = read_interaction_meta(root)
        for index in range(4):
            item = dataset[index]
            # the item names the annotated actor in its own (possibly swapped) person order
            assert item["persons"][item["actor"] - 1] == meta[item["id"]].actor
