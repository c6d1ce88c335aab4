"""configs/text compose into the real job config and build the cache (tiny tower only)."""

from __future__ import annotations

from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf

from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder, TextFeatureCache
from intermask.train import CONFIG_DIR


def _compose(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose("train_vq", overrides=[*overrides, "paths.output_dir=/tmp/unused"])


def test_paper_config_is_the_papers_clip():
    cfg = _compose(["+text=clip_vit_l14_336", "paths.data_dir=/data"])
    encoder = cfg.text.encoder
    assert encoder._target_ == "intermask.text.clip_encoder.FrozenCLIPTextEncoder"
    assert encoder.model_name == "ViT-L-14-336" and encoder.pretrained == "openai"
    assert encoder.context_length == 77 and encoder.quick_gelu is True
    OmegaConf.resolve(cfg)
    assert cfg.text.cache_dir == "/data/text_cache"


def test_tiny_config_instantiates_offline(tmp_path):
    cfg = _compose(["+text=tiny_random", f"paths.data_dir={tmp_path}"])
    cache = instantiate(cfg.text)
    assert isinstance(cache, TextFeatureCache) and isinstance(cache.encoder, FrozenCLIPTextEncoder)
    assert cache.encoder.model_name == TINY_MODEL_NAME and cache.encoder.source == "random(seed=0)"
    assert cache.directory.parent == tmp_path / "text_cache"
    assert cache.get_or_encode(["a person waves"]).features.shape == (1, 77, 64)
