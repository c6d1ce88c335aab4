"""The released HumanML3D matcher (t2m/text_mot_match/model/finest.tar + Comp_v6_KLD01/meta):
every key of the released layout (data/t2m_humanml3d_finest_keys.txt) maps; missing files and
mismatched keys are reported by name."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from evaluator_builders import CAPTIONS, TOKENS, WORDS, humanml3d_batch

from intermask.data.errors import DataError
from intermask.evaluator import CheckpointMismatchError, HumanML3DMatcher, load_evaluator
from intermask.evaluator.checkpoints import T2M_PARTS

KEY_LIST = Path(__file__).parent / "data" / "t2m_humanml3d_finest_keys.txt"


def released_keys() -> dict[str, tuple[int, ...]]:
    """``<part>.<key>`` -> shape, from the key list."""
    keys = {}
    for line in KEY_LIST.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, shape = line.split()
            keys[name] = tuple(int(size) for size in shape.split(","))
    return keys


def random_state(seed: int = 0) -> dict[str, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    return {k: torch.randn(shape, generator=generator) for k, shape in released_keys().items()}


def write_finest_tar(path: Path, state: dict[str, torch.Tensor]) -> Path:
    """T2M's layout: one state dict per part, optimizer states, epoch and iteration."""
    parts = {part: {} for part in T2M_PARTS}
    for name, tensor in state.items():
        part, key = name.split(".", 1)
        parts[part][key] = tensor
    path.parent.mkdir(parents=True, exist_ok=True)
    optimizers = {f"opt_{p}": {"state": {}, "param_groups": []} for p in T2M_PARTS}
    torch.save({**parts, **optimizers, "epoch": 199, "iter": 26000}, path)
    return path


def write_release(root: Path, state: dict[str, torch.Tensor]) -> tuple[Path, np.ndarray]:
    """The release tree: t2m/text_mot_match/model/finest.tar, t2m/Comp_v6_KLD01/meta/*.npy and
    glove/our_vab_*; -> (finest.tar, (2, 263) mean and std)."""
    path = write_finest_tar(root / "t2m" / "text_mot_match" / "model" / "finest.tar", state)
    rng = np.random.default_rng(0)
    statistics = np.stack([rng.normal(size=263), rng.uniform(0.5, 1.5, size=263)])
    meta = root / "t2m" / "Comp_v6_KLD01" / "meta"
    meta.mkdir(parents=True)
    np.save(meta / "mean.npy", statistics[0])
    np.save(meta / "std.npy", statistics[1])
    glove = root / "glove"
    glove.mkdir()
    np.save(glove / "our_vab_data.npy", rng.normal(size=(len(WORDS), 300)).astype(np.float32))
    (glove / "our_vab_words.pkl").write_bytes(pickle.dumps(WORDS))
    (glove / "our_vab_idx.pkl").write_bytes(pickle.dumps({w: i for i, w in enumerate(WORDS)}))
    return path, statistics


@pytest.fixture(scope="module")
def release(tmp_path_factory) -> tuple[Path, dict[str, torch.Tensor], np.ndarray]:
    state = random_state()
    path, statistics = write_release(tmp_path_factory.mktemp("release"), state)
    return path, state, statistics


def test_the_key_list_is_the_paper_architecture():
    keys = released_keys()
    assert len(keys) == 42 and sum(torch.Size(s).numel() for s in keys.values()) == 21_690_560
    own = {k: tuple(v.shape) for k, v in HumanML3DMatcher().state_dict().items()}
    assert {k: own[k] for k in keys} == keys
    assert sorted(set(own) - set(keys)) == ["has_statistics", "mean", "std"]


def test_every_released_key_lands(release):
    path, state, statistics = release
    glove = path.parents[3] / "glove"
    evaluator = load_evaluator(path, glove_dir=glove)  # HumanML3D: read from the 259 input width
    net = evaluator.net
    assert isinstance(net, HumanML3DMatcher) and evaluator.dataset == "humanml3d"
    assert evaluator.name == "t2m_gru_humanml3d+glove[released]"
    own = net.state_dict()
    landed = [k for k, v in state.items() if torch.equal(own[k], v)]
    assert landed == list(state)
    # the meta statistics (float64 files) became the float32 buffers
    assert torch.equal(net.mean, torch.from_numpy(statistics[0]).float())
    assert torch.equal(net.std, torch.from_numpy(statistics[1]).float())
    vectors = np.load(glove / "our_vab_data.npy")
    assert torch.equal(net.word_embedding.weight, torch.from_numpy(vectors))
    assert not net.word_embedding.weight.requires_grad and not evaluator.training
    motion, lengths = humanml3d_batch()
    assert evaluator.encode_motion(motion, lengths).shape == (3, 512)
    assert evaluator.encode_text(CAPTIONS, TOKENS).shape == (3, 512)


def test_a_missing_key_and_a_wrong_shape_are_named(release, tmp_path):
    path, state, _ = release
    glove = path.parents[3] / "glove"
    broken = dict(state)
    del broken["motion_encoder.hidden"]
    broken["movement_encoder.main.0.weight"] = torch.zeros(512, 263, 4)  # contacts not dropped
    bad = write_finest_tar(tmp_path / "finest.tar", broken)
    meta = path.parents[2] / "Comp_v6_KLD01" / "meta"
    with pytest.raises(
        CheckpointMismatchError,
        match=r"finest.tar: checkpoint does not match HumanML3DMatcher: missing \(1\): "
        r"motion_encoder.hidden; shape mismatch \(1\): movement_encoder.main.0.weight "
        r"file \[512, 263, 4\] vs model \[512, 259, 4\]",
    ):
        load_evaluator(bad, dataset="humanml3d", glove_dir=glove, meta_dir=meta)
    with pytest.raises(
        ValueError,
        match=r"movement encoder reads 263 channels \(672 interx, 259 humanml3d\); pass dataset=",
    ):
        load_evaluator(bad, glove_dir=glove, meta_dir=meta)


def test_missing_meta_and_glove_files_are_named(release, tmp_path):
    path, state, _ = release
    glove = path.parents[3] / "glove"
    with pytest.raises(ValueError, match="pass glove_dir=<folder with our_vab_data.npy"):
        load_evaluator(path)
    with pytest.raises(FileNotFoundError, match="our_vab_data.npy: GloVe vectors not found"):
        load_evaluator(path, glove_dir=tmp_path)
    # a finest.tar without the release's meta folder
    alone = write_finest_tar(tmp_path / "t2m" / "text_mot_match" / "model" / "finest.tar", state)
    expected = tmp_path / "t2m" / "Comp_v6_KLD01" / "meta" / "mean.npy"
    with pytest.raises(
        FileNotFoundError,
        match=rf"{expected}, .*std.npy: the released evaluator's statistics are missing.*"
        r"pass meta_dir=<folder with mean.npy and std.npy>",
    ):
        load_evaluator(alone, glove_dir=glove)
    np.save(tmp_path / "mean.npy", np.zeros(262))
    np.save(tmp_path / "std.npy", np.ones(263))
    with pytest.raises(DataError, match=r"mean.npy: expected shape \(263,\), got \(262,\)"):
        load_evaluator(alone, glove_dir=glove, meta_dir=tmp_path)


def test_dataset_and_net_must_agree(release):
    path, _, _ = release
    glove = path.parents[3] / "glove"
    net = HumanML3DMatcher(word_vectors="glove", glove_dir=str(glove))
    with pytest.raises(ValueError, match="dataset='interx', but net is the humanml3d matcher"):
        load_evaluator(path, net=net, dataset="interx")
    with pytest.raises(ValueError, match=r"dataset must be one of \['humanml3d', 'interx'\]"):
        load_evaluator(path, dataset="kit")
    with pytest.raises(
        ValueError, match="meta_dir is for the HumanML3D matcher, this one is interx"
    ):
        load_evaluator(path, dataset="interx", glove_dir=glove, meta_dir=glove)
