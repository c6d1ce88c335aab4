"""The real readers on the embedded synthetic dataset (the session fixtures of tests/conftest.py)."""

import torch

from intermask.data.datamodule import InteractionDataModule
from intermask.data.interhuman import InterHumanDataset
from intermask.data.interx import InterXDataset
from intermask.data.validation import check_dataset
from intermask.motion.skeleton import FACE_JOINTS


def test_three_distinct_captions_across_draws(synthetic_interhuman_root):
    ds = InterHumanDataset(root=synthetic_interhuman_root, split="train", swap_persons=False)
    drawn = {ds[(0, epoch)]["caption"] for epoch in range(40)}
    assert drawn == set(ds.captions[0]) and len(drawn) == 3


def test_synthetic_interhuman_is_valid_and_canonical(synthetic_interhuman_root):
    assert check_dataset(synthetic_interhuman_root, "interhuman") == []
    ds = InterHumanDataset(root=synthetic_interhuman_root, split="train", swap_persons=False)
    for index in range(len(ds)):
        item = ds[index]
        length = item["length"]
        assert item["motion"].shape == (2, 300, 262) and 14 <= length <= 299
        feats = item["motion"][:, :length]
        pos = feats[..., :66].reshape(2, length, 22, 3)
        vel = feats[..., 66:132].reshape(2, length, 22, 3)
        assert pos[0, 0, 0, [0, 2]].abs().max() < 1e-5
        across = pos[0, 0, FACE_JOINTS[0]] - pos[0, 0, FACE_JOINTS[1]]
        assert across[0] < 0 and abs(across[2]) < 1e-5  # facing +Z
        assert pos[..., 1].amin(dim=(1, 2)).abs().max() < 1e-4  # each person floored at 0
        assert torch.allclose(vel[:, :-1], pos[:, 1:] - pos[:, :-1], atol=1e-5)
        assert {"action", "action_id", "actor"} <= item.keys() and item["actor"] in (1, 2)


def test_synthetic_interhuman_datamodule(synthetic_interhuman_root):
    dm = InteractionDataModule(
        dataset="interhuman", root=str(synthetic_interhuman_root), batch_size=4
    )
    dm.prepare_data()
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))
    assert batch["motion"].shape == (4, 2, 300, 262)
    assert len(set(dm.datasets["train"].captions[0])) == 3
    window = InteractionDataModule(
        dataset="interhuman", root=str(synthetic_interhuman_root), batch_size=4, mode="window"
    )
    assert next(iter(window.train_dataloader()))["motion"].shape == (4, 64, 262)


def test_synthetic_interx(synthetic_interx_root):
    assert check_dataset(synthetic_interx_root, "interx") == []
    ds = InterXDataset(root=synthetic_interx_root, split="train")
    for index in range(len(ds)):
        item = ds[index]
        assert item["motion"].shape == (2, 150, 56, 6)
        assert item["length"] % 4 == 0 and 20 <= item["length"] <= 148
        assert item["actor"] in (1, 2) and 0 <= item["action_id"]


def test_two_person_windows_hold_both_single_person_windows(synthetic_interhuman_root):
    pairs = InterHumanDataset(
        root=synthetic_interhuman_root, split="val", mode="window", window_persons=2
    )
    singles = InterHumanDataset(root=synthetic_interhuman_root, split="val", mode="window")
    assert len(pairs) * 2 == len(singles)
    item = pairs[len(pairs) - 1]
    assert item["motion"].shape == (64, 2, 262) and item["person"] == 0
    sequence, start = int(pairs.windows.sequence[-1]), int(pairs.windows.start[-1])
    for person in (0, 1):
        match = (singles.windows.sequence == 2 * sequence + person) & (
            singles.windows.start == start
        )
        assert torch.equal(singles[int(match.nonzero()[0][0])]["motion"], item["motion"][:, person])
