import importlib

import lightning as L
import numpy as np
import pytest
import torch
from builders import write_interhuman, write_interx

from intermask.data.datamodule import InteractionDataModule
from intermask.data.errors import DataError
from intermask.data.interhuman import InterHumanDataset
from intermask.data.interx import InterXDataset

IH_SPLITS = {"train": (40, 80, 320, 90, 70), "val": (30, 60, 400), "test": (50, 310, 45)}


@pytest.fixture(scope="module")
def ih_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("dm_ih") / "InterHuman"
    write_interhuman(root, splits=IH_SPLITS, meta=True)
    return root


@pytest.fixture(scope="module")
def ix_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("dm_ix") / "InterX"
    write_interx(root, splits={"train": (40, 80, 200), "val": (30, 60), "test": (50, 160, 44)})
    return root


def make(root, **kwargs):
    args = dict(dataset="interhuman", root=str(root), batch_size=2)
    args.update(kwargs)
    return InteractionDataModule(**args)


def test_interhuman_fit_computes_stats_and_yields_batches(ih_root):
    dm = make(ih_root)
    dm.prepare_data()
    assert (ih_root / "stats" / "mean.npy").is_file() and (
        ih_root / "stats" / "stats.json"
    ).is_file()
    dm.setup("fit")
    assert dm.normalizer is not None and dm.normalizer.feature_shape == (262,)
    assert set(dm.datasets) == {"train", "val"}
    assert len(dm.datasets["train"]) == 10  # mirrored copies in train
    assert len(dm.datasets["val"]) == 3  # none in val
    batch = next(iter(dm.train_dataloader()))
    assert batch["motion"].shape == (2, 2, 300, 262) and batch["motion"].dtype == torch.float32
    assert batch["length"].dtype == torch.int64 and batch["length"].shape == (2,)
    assert isinstance(batch["caption"], list) and all(isinstance(c, str) for c in batch["caption"])
    assert {"id", "mirrored", "persons", "action", "action_id", "actor"} <= batch.keys()
    # Normalized features de-normalize to canonical ones: velocities = position differences.
    feats = dm.normalizer.denormalize(batch["motion"][0, :, : batch["length"][0]])
    pos, vel = feats[..., :66], feats[..., 66:132]
    assert torch.allclose(vel[:, :-1], pos[:, 1:] - pos[:, :-1], atol=1e-4)
    assert len(dm.val_dataloader()) == 2


def _batches(loader):
    return [(b["motion"].clone(), list(b["caption"]), b["id"]) for b in loader]


def _same(a, b):
    return len(a) == len(b) and all(
        torch.equal(x[0], y[0]) and x[1:] == y[1:] for x, y in zip(a, b, strict=True)
    )


def test_deterministic_eval_passes(ih_root):
    one, two = make(ih_root, eval_batch_size=3), make(ih_root, eval_batch_size=3, num_workers=2)
    first = _batches(one.eval_dataloader("test", epoch=0, drop_last=False))
    assert _same(
        first, _batches(two.eval_dataloader("test", epoch=0, drop_last=False))
    )  # workers do not matter
    assert _same(first, _batches(one.eval_dataloader("test", epoch=0, drop_last=False)))
    assert not _same(first, _batches(one.eval_dataloader("test", epoch=1, drop_last=False)))
    assert _same(_batches(one.test_dataloader()), _batches(two.test_dataloader()))


def test_eval_dataloader_shuffles_and_drops_last(ih_root):
    dm = make(ih_root)
    loader = dm.eval_dataloader("test", batch_size=2, epoch=0)
    assert len(loader) == 1
    ids = [next(iter(dm.eval_dataloader("test", batch_size=3, epoch=e)))["id"] for e in range(6)]
    assert len({tuple(i) for i in ids}) > 1  # the order depends on (seed, epoch)


def test_window_mode_batches(ih_root):
    dm = make(ih_root, mode="window", batch_size=4)
    batch = next(iter(dm.train_dataloader()))
    assert batch["motion"].shape == (4, 64, 262)
    assert batch["person"].tolist() and set(batch["person"].tolist()) <= {1, 2}


def test_missing_stats_without_compute_names_the_command(tmp_path):
    root = tmp_path / "ih"
    write_interhuman(root, splits={"train": (20,), "val": (20,), "test": (20,)})
    dm = make(root, compute_stats=False)
    dm.prepare_data()
    with pytest.raises(
        DataError,
        match=r"stats: normalization statistics not found; compute them with `intermask data stats",
    ):
        dm.setup("fit")


def test_reference_stats_are_used(ih_root, tmp_path):
    rng = np.random.default_rng(0)
    mean, std = rng.normal(size=262).astype(np.float32), rng.uniform(1, 2, 262).astype(np.float32)
    np.save(tmp_path / "global_mean.npy", mean)
    np.save(tmp_path / "global_std.npy", std)
    dm = make(ih_root, stats_dir=str(tmp_path), compute_stats=False)
    dm.setup("test")
    assert set(dm.datasets) == {"test"}
    assert np.allclose(dm.normalizer.mean.numpy(), mean)


def test_interx_batches_without_normalization(ix_root):
    dm = make(ix_root, dataset="interx", batch_size=2, mirror=True)
    dm.prepare_data()
    assert not (ix_root / "stats").exists()
    dm.setup("fit")
    assert dm.normalizer is None and dm.feature_shape == (56, 6)
    batch = next(iter(dm.train_dataloader()))
    assert batch["motion"].shape == (2, 2, 150, 56, 6)
    assert all(length % 4 == 0 for length in batch["length"].tolist())
    assert isinstance(batch["tokens"], list) and "/NOUN" in batch["tokens"][0]
    assert batch["persons"].tolist() == [[1, 2], [1, 2]]  # Inter-X default: no person swap
    assert len(dm.datasets["train"]) == 3  # no mirrored copies for Inter-X


def test_invalid_arguments(ih_root):
    with pytest.raises(ValueError, match="dataset must be"):
        make(ih_root, dataset="synthetic")
    with pytest.raises(ValueError, match="mode must be"):
        make(ih_root, mode="pairs")


class RecordingReader(InterHumanDataset):
    """The InterHuman reader, recording every construction (split, mode, mirror, swap)."""

    built: list[tuple[str, str, bool, bool]] = []

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        RecordingReader.built.append((self.split, self.mode, self.mirror, self.swap_persons))


def test_an_injected_reader_serves_every_split_and_the_statistics(ih_root, tmp_path):
    RecordingReader.built.clear()
    dm = make(ih_root, reader=RecordingReader, stats_dir=str(tmp_path / "stats"))
    dm.prepare_data()  # statistics missing: computed by the injected reader, augmentation off
    assert RecordingReader.built == [("train", "interaction", False, False)]
    dm.setup("fit")
    assert RecordingReader.built[1:] == [
        ("train", "interaction", True, True),  # mirrored copies in train only
        ("val", "interaction", False, True),
    ]
    assert type(dm.datasets["val"]) is RecordingReader and len(dm.datasets["train"]) == 10


def test_reader_defaults_come_from_the_reader_class(ih_root, ix_root):
    ih, ix = (
        make(ih_root),
        make(ix_root, dataset="interx", reader="intermask.data.interx.InterXDataset"),
    )
    assert ih.reader is InterHumanDataset and ix.reader is InterXDataset
    assert (ih.max_length, ih.min_length, ih.swap_persons, ih.normalize, ih.mirror) == (
        300,
        15,
        True,
        True,
        True,
    )
    assert (ix.max_length, ix.min_length, ix.swap_persons, ix.normalize, ix.mirror) == (
        150,
        24,
        False,
        False,
        False,
    )
    assert (ih.feature_shape, ix.feature_shape) == ((262,), (56, 6))


def test_an_injected_reader_is_checked(ih_root):
    with pytest.raises(
        ValueError,
        match=r"reader intermask.data.interx.InterXDataset reads 'interx' features, but the "
        r"dataset kind is 'interhuman': set data.dataset=interx",
    ):
        make(ih_root, reader="intermask.data.interx.InterXDataset")
    with pytest.raises(
        TypeError,
        match=r"reader 'intermask.data.common.EpochSampler' is not a subclass of "
        r"intermask.data.reader.ClipReader",
    ):
        make(ih_root, reader="intermask.data.common.EpochSampler")
    with pytest.raises(ValueError, match=r"reader 'nowhere.Reader' cannot be imported \(No module"):
        make(ih_root, reader="nowhere.Reader")
    with pytest.raises(ValueError, match=r"dotted path 'package.module.Class', got 'Reader'"):
        make(ih_root, reader="Reader")


def test_synthesize_if_missing_calls_the_generator(tmp_path, monkeypatch):
    synthetic = importlib.import_module("intermask.data.synthetic")
    calls = []

    def fake_generate(out, format, clips, seed):
        calls.append((out, format, clips, seed))
        write_interhuman(out, splits={"train": (20, 30), "val": (20,), "test": (20,)})

    monkeypatch.setattr(synthetic, "generate_dataset", fake_generate, raising=False)
    root = tmp_path / "data" / "synthetic" / "interhuman"
    dm = make(root, synthesize_if_missing=True, synthetic_clips=7, synthetic_seed=5)
    dm.prepare_data()
    assert calls == [(root, "interhuman", 7, 5)]
    assert (root / "stats" / "mean.npy").is_file()
    dm.prepare_data()  # present now: not generated again
    assert len(calls) == 1


class _Recorder(L.LightningModule):
    def __init__(self):
        super().__init__()
        self.weight = torch.nn.Parameter(torch.zeros(()))
        self.seen: list[tuple[int, str, str]] = []

    def training_step(self, batch, batch_idx):
        for clip_id, caption in zip(batch["id"], batch["caption"], strict=True):
            self.seen.append((self.current_epoch, clip_id, caption))
        return (self.weight - batch["motion"].mean()) ** 2

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.0)


def test_lightning_redraws_items_every_epoch(ih_root, tmp_path):
    dm = make(ih_root, batch_size=10, mirror=False)
    model = _Recorder()
    trainer = L.Trainer(
        max_epochs=4,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=0,
        default_root_dir=tmp_path,
    )
    trainer.fit(model, datamodule=dm)
    per_epoch = [sorted((i, c) for e, i, c in model.seen if e == epoch) for epoch in range(4)]
    assert all(len(p) == 5 for p in per_epoch)
    assert len({tuple(p) for p in per_epoch}) > 1  # captions re-drawn across epochs
