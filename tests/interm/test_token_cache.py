"""Inter-M's token cache: hits equal fresh encodings, later epochs hit, a new VQ empties it."""

from __future__ import annotations

from functools import partial

import pytest
import torch
from hydra import compose, initialize_config_dir
from torch.utils.data import DataLoader

from intermask.data.common import EpochSampler
from intermask.data.interhuman import InterHumanDataset
from intermask.data.interx import InterXDataset
from intermask.interm.model import InterMTransformer
from intermask.interm.module import InterMModule
from intermask.interm.token_cache import TokenCache
from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder
from intermask.text.cache import TextFeatureCache
from intermask.train import CONFIG_DIR
from intermask.vq.convolutions import MotionDecoder, MotionEncoder
from intermask.vq.model import MotionVQVAE
from intermask.vq.quantizers import ResidualQuantizer
from intermask.vq.views import InterHumanView, InterXView

CODEBOOK = 32


@pytest.fixture(scope="module")
def text_encoder() -> FrozenCLIPTextEncoder:
    return FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=None, seed=0)


def _vq(interx: bool = False, seed: int = 0) -> MotionVQVAE:
    torch.manual_seed(seed)
    if interx:
        view, joints, encoder_extra = InterXView(), 56, {"joint_kernel": 6, "joint_stride": 3}
        decoder_extra, channels = {"joint_scales": [3.5, 3.3]}, 6
    else:
        view, joints, encoder_extra = InterHumanView(), 22, {}
        decoder_extra, channels = {}, 12
    vq = MotionVQVAE(
        view=view,
        encoder=MotionEncoder(num_joints=joints, in_channels=channels, width=16, **encoder_extra),
        quantizer=ResidualQuantizer(num_quantizers=1, codebook_size=CODEBOOK, dim=16),
        decoder=MotionDecoder(num_joints=joints, out_channels=channels, width=16, **decoder_extra),
    )
    vq.train()(torch.randn(4, 64, *view.feature_shape))  # codebooks from data
    return vq.eval()


def _module(text_encoder, tmp_path, *, token_cache: bool = True, interx: bool = False):
    torch.manual_seed(1)
    net = InterMTransformer(
        codebook_size=CODEBOOK,
        width=32,
        depth=1,
        heads=2,
        ff=64,
        dropout=0.0,
        token_embed_dim=32,
        text_dim=64,
        text_layers=1,
        text_heads=2,
        text_ff=64,
        text_dropout=0.0,
    )
    return InterMModule(
        net=net,
        vq=_vq(interx),
        text=TextFeatureCache(encoder=text_encoder, cache_dir=tmp_path / "text"),
        optimizer=partial(torch.optim.AdamW, lr=2e-4),
        warmup_fraction=0.25,
        token_cache=token_cache,
    )


def _epochs(dataset, epochs: int):
    """Batches of ``epochs`` shuffled passes, as training draws them (crops re-drawn per epoch)."""
    sampler = EpochSampler(len(dataset), shuffle=True, seed=0)
    for epoch in range(epochs):
        sampler.set_epoch(epoch)
        yield epoch, list(DataLoader(dataset, batch_size=8, sampler=sampler))


def _count_encodes(module: InterMModule) -> list[int]:
    """Counts the person crops the VQ encodes (patched onto the module's VQ)."""
    count, encode = [0], module.vq.encode

    def counting(features, lengths=None):
        count[0] += features.shape[0]
        return encode(features, lengths)

    module.vq.encode = counting
    return count


def _fresh(module: InterMModule, batch) -> torch.Tensor:
    """Tokens without the cache: the batch minus the crop identity."""
    return module.tokenize({k: batch[k] for k in ("motion", "length")})[0]


def test_cached_tokens_equal_fresh_ones_over_random_crops(
    synthetic_interhuman_root, text_encoder, tmp_path
):
    # 64-frame crops of 62..~200-frame clips: random starts, mirroring and both reference persons
    dataset = InterHumanDataset(
        root=synthetic_interhuman_root, split="train", max_length=64, mirror=True
    )
    module = _module(text_encoder, tmp_path)
    for _, batches in _epochs(dataset, 3):
        module.on_train_epoch_start()
        for batch in batches:
            cached, steps = module.tokenize(batch)
            assert torch.equal(cached, _fresh(module, batch))
            assert torch.equal(steps, batch["length"] // 4)
    assert module.token_cache.hits > 0  # some crops came back in the third epoch


def test_second_epoch_hits_the_cache_and_encodes_nothing(
    synthetic_interhuman_root, text_encoder, tmp_path
):
    # crops as long as the clips and no person swap: one crop per item, met again every epoch
    dataset = InterHumanDataset(
        root=synthetic_interhuman_root, split="train", max_length=400, swap_persons=False
    )
    module = _module(text_encoder, tmp_path)
    encoded = _count_encodes(module)
    for epoch, batches in _epochs(dataset, 2):
        module.on_train_epoch_start()
        tokens = [module.tokenize(batch)[0] for batch in batches]
        crops = 2 * len(dataset)
        assert module.token_cache.lookups == crops
        assert module.token_cache.hits == (0 if epoch == 0 else crops)
        assert encoded[0] == crops  # all encoded in the first epoch, none in the second
    assert all(torch.equal(t, _fresh(module, b)) for t, b in zip(tokens, batches, strict=True))


def test_interx_crops_are_cached_exactly(synthetic_interx_root, text_encoder, tmp_path):
    # random starts and the reference's length jitter; no mirror, no reference person
    dataset = InterXDataset(root=synthetic_interx_root, split="train", max_length=64)
    module = _module(text_encoder, tmp_path, interx=True)
    for _, batches in _epochs(dataset, 3):
        for batch in batches:
            assert torch.equal(module.tokenize(batch)[0], _fresh(module, batch))
    assert len(module.token_cache) > 0


def _short_clip_batch(root) -> dict:
    dataset = InterHumanDataset(root=root, split="train", max_length=400, swap_persons=False)
    return next(iter(DataLoader(dataset, batch_size=8)))


def test_another_vq_empties_the_cache(synthetic_interhuman_root, text_encoder, tmp_path):
    batch = _short_clip_batch(synthetic_interhuman_root)
    module = _module(text_encoder, tmp_path)
    old = module.tokenize(batch)[0]
    assert len(module.token_cache) == 16
    module._frozen.vq = _vq(seed=5)  # a different tokenizer object
    new = module.tokenize(batch)[0]
    assert module.token_cache.hits == 0 and not torch.equal(old, new)
    assert torch.equal(new, _fresh(module, batch))


def test_changed_vq_weights_empty_the_cache_at_the_next_epoch(
    synthetic_interhuman_root, text_encoder, tmp_path
):
    batch = _short_clip_batch(synthetic_interhuman_root)
    module = _module(text_encoder, tmp_path)
    module.tokenize(batch)
    module.vq.load_state_dict(_vq(seed=5).state_dict())  # same object, other weights
    module.on_train_epoch_start()
    assert len(module.token_cache) == 0
    assert torch.equal(module.tokenize(batch)[0], _fresh(module, batch))
    assert module.token_cache.hits == 0


def test_batches_without_crop_identity_and_the_switch_bypass_the_cache(
    synthetic_interhuman_root, text_encoder, tmp_path
):
    batch = _short_clip_batch(synthetic_interhuman_root)
    module = _module(text_encoder, tmp_path)
    module.tokenize({k: batch[k] for k in ("motion", "length", "caption")})
    assert len(module.token_cache) == 0
    off = _module(text_encoder, tmp_path, token_cache=False)
    assert off.token_cache is None and off.hparams.token_cache is False
    assert torch.equal(off.tokenize(batch)[0], module.tokenize(batch)[0])


def test_full_cache_keeps_what_it_has():
    cache = TokenCache(codebook_size=CODEBOOK, max_entries=1)
    first, second = ("a", False, 0, 1, 1, 64, 64), ("a", False, 0, 1, 2, 64, 64)
    cache.put(first, torch.full((5, 16), 3))
    cache.put(second, torch.full((5, 16), 4))
    assert len(cache) == 1 and cache.get(second) is None
    assert torch.equal(cache.get(first), torch.full((5, 16), 3))
    with pytest.raises(ValueError, match="max_entries must be >= 1, got 0"):
        TokenCache(codebook_size=CODEBOOK, max_entries=0)


def test_generator_configs_switch_the_cache_on():
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train_gen", overrides=["experiment=gen_demo"])
    assert cfg.model.token_cache is True
