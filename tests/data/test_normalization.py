import json

import numpy as np
import pytest
import torch
from builders import write_interhuman, write_interx

from intermask.data.errors import DataError
from intermask.data.interhuman import InterHumanDataset
from intermask.data.normalization import Normalizer, compute_normalizer
from intermask.data.statistics import compute_and_save_stats
from intermask.motion.skeleton import MIRROR_PERMUTATION


def _stats(shape=(262,), seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=shape), rng.uniform(0.1, 2.0, size=shape)


def test_round_trip_tensor_and_array():
    mean, std = _stats()
    norm = Normalizer(mean, std)
    x = torch.randn(2, 300, 262, dtype=torch.float64)
    z = norm.normalize(x)
    assert torch.allclose(z[0, 0], (x[0, 0] - torch.from_numpy(mean)) / torch.from_numpy(std))
    assert torch.allclose(norm.denormalize(z), x)
    a = np.random.default_rng(1).normal(size=(5, 262)).astype(np.float32)
    back = norm.denormalize(norm.normalize(a))
    assert back.dtype == np.float32 and np.allclose(back, a, atol=1e-5)


def test_round_trip_float32_tensor_keeps_dtype():
    mean, std = _stats((56, 6))
    norm = Normalizer(mean, std)
    x = torch.randn(3, 56, 6)
    z = norm.normalize(x)
    assert z.dtype == torch.float32
    assert torch.allclose(norm.denormalize(z), x, atol=1e-5)


def test_identity():
    norm = Normalizer.identity((56, 6))
    x = torch.randn(4, 56, 6)
    assert norm.is_identity
    assert torch.equal(norm.normalize(x), x)


def test_wrong_input_shape():
    norm = Normalizer(*_stats())
    with pytest.raises(ValueError, match=r"expects trailing dims \(262,\).*\(2, 261\)"):
        norm.normalize(torch.zeros(2, 261))


@pytest.mark.parametrize(
    ("mean", "std", "match"),
    [
        (np.zeros(262), np.zeros(261), r"mean shape \(262,\) != std shape \(261,\)"),
        (np.full(262, np.nan), np.ones(262), "mean has 262 NaN/Inf"),
        (np.zeros(262), np.r_[np.ones(261), np.inf], "std has 1 NaN/Inf"),
        (
            np.zeros(262),
            np.r_[np.ones(10), 0.0, np.ones(251)],
            r"zero/negative std at flat indices \[10\]",
        ),
    ],
)
def test_bad_stats(mean, std, match):
    with pytest.raises(DataError, match=match):
        Normalizer(mean, std)


def test_save_load_and_reference_names(tmp_path):
    mean, std = _stats()
    Normalizer(mean, std).save(tmp_path / "ours", provenance={"dataset": "interhuman"})
    loaded = Normalizer.load(tmp_path / "ours", feature_shape=(262,))
    assert np.allclose(loaded.mean.numpy(), mean.astype(np.float32))
    info = json.loads((tmp_path / "ours" / "stats.json").read_text())
    assert info["dataset"] == "interhuman" and info["shape"] == [262]

    ref = tmp_path / "ref"
    ref.mkdir()
    np.save(ref / "global_mean.npy", mean.astype(np.float32))
    np.save(ref / "global_std.npy", std.astype(np.float32))
    loaded = Normalizer.load(ref, feature_shape=(262,))
    assert np.allclose(loaded.std.numpy(), std.astype(np.float32))
    assert "global_mean.npy" in loaded.source


def test_load_errors(tmp_path):
    with pytest.raises(DataError, match="no normalization statistics"):
        Normalizer.load(tmp_path)
    np.save(tmp_path / "global_mean.npy", np.zeros(263))
    np.save(tmp_path / "global_std.npy", np.ones(263))
    with pytest.raises(DataError, match=r"global_mean.npy: expected shape \(262,\), got \(263,\)"):
        Normalizer.load(tmp_path, feature_shape=(262,))
    np.save(tmp_path / "global_mean.npy", np.zeros(262))
    np.save(tmp_path / "global_std.npy", np.zeros(262))
    with pytest.raises(DataError, match="global_std.npy.*zero/negative std"):
        Normalizer.load(tmp_path, feature_shape=(262,))
    (tmp_path / "mean.npy").write_text("not numpy")
    (tmp_path / "std.npy").write_text("not numpy")
    with pytest.raises(DataError, match=r"mean.npy: cannot read as .npy"):
        Normalizer.load(tmp_path)


def test_compute_normalizer_matches_numpy_and_floors_constant_features():
    rng = np.random.default_rng(0)
    seqs = [rng.normal(size=(n, 2, 4)) for n in (5, 9)]
    seqs[0][..., 3] = 1.0
    seqs[1][..., 3] = 1.0
    norm, info = compute_normalizer(seqs, feature_shape=(4,), min_std=1e-3)
    flat = np.concatenate([s.reshape(-1, 4) for s in seqs])
    assert np.allclose(norm.mean.numpy(), flat.mean(0))
    assert np.allclose(norm.std.numpy()[:3], flat.std(0)[:3])
    assert norm.std[3].item() == pytest.approx(1e-3)
    assert info == {"num_sequences": 2, "num_frames": 28, "min_std": 1e-3, "floored_dims": 1}


@pytest.fixture(scope="module")
def interhuman_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("ih")
    write_interhuman(root, splits={"train": (30, 45, 60), "val": (20,), "test": (20,)})
    return root


def test_interhuman_stats_over_mirrored_copies_and_both_references(interhuman_root, tmp_path):
    norm = compute_and_save_stats(interhuman_root, dataset="interhuman", out_dir=tmp_path)
    ds = InterHumanDataset(root=interhuman_root, split="train", swap_persons=False)
    variants = [
        ds.clip_features(c, mirror=m, swap=s).reshape(-1, 262).double()
        for c in range(3)
        for m in (False, True)
        for s in (False, True)
    ]
    frames = torch.cat(variants)
    assert torch.allclose(norm.mean, frames.mean(0), atol=1e-5)
    assert torch.allclose(norm.std, frames.std(0, unbiased=False).clamp_min(1e-3), atol=1e-5)
    # Mirrored copies included: mean x of joint j is minus the mean x of its mirror partner.
    mean_pos = norm.mean[:66].reshape(22, 3)
    assert torch.allclose(mean_pos[:, 0], -mean_pos[list(MIRROR_PERMUTATION), 0], atol=1e-5)
    info = json.loads((tmp_path / "stats.json").read_text())
    assert info["num_clips"] == 3 and info["num_sequences"] == 12 and info["split"] == "train"
    assert info["num_frames"] == 2 * 4 * (29 + 44 + 59)
    assert Normalizer.load(tmp_path, feature_shape=(262,)).feature_shape == (262,)


def test_interx_stats(tmp_path):
    root = tmp_path / "ix"
    write_interx(root, splits={"train": (30, 40), "val": (30,), "test": (30,)})
    norm = compute_and_save_stats(root, dataset="interx")
    assert norm.feature_shape == (56, 6)
    assert (root / "stats" / "mean.npy").is_file()
    # Rows 22..24 (jaw, eyes) are zero rotations: constant 6D identity, floored std.
    assert torch.allclose(
        norm.mean[22], torch.tensor([1.0, 0, 0, 1, 0, 0], dtype=torch.float64), atol=1e-6
    )
    assert torch.allclose(norm.std[22], torch.full((6,), 1e-3, dtype=torch.float64))
