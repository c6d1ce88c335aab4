"""TextFeatureCache: hits return what the misses returned, only misses are encoded, files persist."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch

from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder, TextFeatureCache

CAPTIONS = ["a person waves", "two people shake hands", "one pushes the other"]


class EncoderSpy:
    """Counts the captions that reach the encoder."""

    def __init__(self, encoder: FrozenCLIPTextEncoder) -> None:
        self.encoder, self.calls = encoder, []
        self.identity, self.device = encoder.identity, encoder.device

    def encode(self, captions):
        self.calls.append(list(captions))
        return self.encoder.encode(captions)


@pytest.fixture
def spy(tiny_encoder) -> EncoderSpy:
    return EncoderSpy(tiny_encoder)


def test_second_call_is_all_hits_and_identical(tmp_path, spy, tiny_encoder):
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path)
    first = cache.get_or_encode(CAPTIONS)
    assert (cache.hits, cache.misses) == (0, 3)
    second = cache.get_or_encode(CAPTIONS)
    assert (cache.hits, cache.misses) == (3, 3) and len(spy.calls) == 1
    for a, b in zip(first, second, strict=True):
        assert torch.equal(a, b)  # a miss is rounded to fp16 like a hit: bitwise equal
    fresh = tiny_encoder.encode(CAPTIONS)
    assert first.features.dtype == torch.float32
    torch.testing.assert_close(first.features, fresh.features, rtol=1e-3, atol=1e-3)  # fp16 storage
    assert torch.equal(first.eot_index, fresh.eot_index)
    assert torch.equal(first.padding_mask, fresh.padding_mask)


def test_hits_and_misses_under_cpu_bf16_autocast(tmp_path, spy):
    """bf16-mixed training on a CPU with native bf16 reads the cache under CPU autocast, which
    refuses fp16 inputs to stack ("Unexpected floating ScalarType"): the demo's generator stage
    died there in its first validation step."""
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path)
    plain = cache.get_or_encode(CAPTIONS[:2])
    with torch.autocast("cpu", dtype=torch.bfloat16):
        mixed = cache.get_or_encode(CAPTIONS)  # two hits and a miss
    assert (cache.hits, cache.misses) == (2, 3)
    assert mixed.features.dtype == torch.float32 and mixed.features.shape[0] == 3
    assert torch.equal(mixed.features[:2], plain.features)  # the hits: the stored fp16, widened


def test_only_misses_are_encoded(tmp_path, spy):
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path)
    cache.get_or_encode(CAPTIONS[:2])
    new = "they dance together"
    features = cache.get_or_encode([CAPTIONS[0], new, CAPTIONS[1], new])
    assert spy.calls == [CAPTIONS[:2], [new]]  # repeated caption encoded once
    assert (cache.hits, cache.misses) == (3, 3)
    expected = cache.get_or_encode([new, CAPTIONS[0]]).features
    assert torch.equal(features.features[[1, 0]], expected)  # rows follow the request order
    assert torch.equal(features.features[1], features.features[3])


def test_misses_are_encoded_in_chunks(tmp_path, spy):
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path, batch_size=2)
    captions = [f"caption {i}" for i in range(5)]
    assert cache.precompute(captions + captions[:2]) == 5
    assert [len(call) for call in spy.calls] == [2, 2, 1]
    assert cache.precompute(captions) == 0


def test_cache_survives_a_new_process(tmp_path, tiny_encoder):
    first = TextFeatureCache(encoder=tiny_encoder, cache_dir=tmp_path).get_or_encode(CAPTIONS)
    rebuilt = FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, seed=0)  # as a new process would
    spy = EncoderSpy(rebuilt)
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path)
    second = cache.get_or_encode(CAPTIONS)
    assert spy.calls == [] and cache.disk_hits == 3 and cache.hits == 3
    assert torch.equal(first.features, second.features) and torch.equal(
        first.eot_index, second.eot_index
    )
    assert not list(tmp_path.rglob("*.tmp"))  # atomic writes leave no temporary files
    assert (cache.directory / "identity.txt").read_text().strip() == tiny_encoder.identity


def test_model_identity_separates_entries(tmp_path, tiny_encoder):
    def stub(identity: str):
        return SimpleNamespace(identity=identity, device=torch.device("cpu"))

    random_tower = TextFeatureCache(encoder=stub("ViT-L-14-336|pretrained=random"))
    real_clip = TextFeatureCache(encoder=stub("ViT-L-14-336|pretrained=openai"))
    other_arch = TextFeatureCache(encoder=stub("ViT-B-32|pretrained=random"))
    keys = {cache.key(CAPTIONS[0]) for cache in (random_tower, real_clip, other_arch)}
    assert len(keys) == 3

    TextFeatureCache(encoder=tiny_encoder, cache_dir=tmp_path).get_or_encode(CAPTIONS)
    other = EncoderSpy(FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, seed=1))
    cache = TextFeatureCache(encoder=other, cache_dir=tmp_path)
    cache.get_or_encode(CAPTIONS)
    assert cache.hits == 0 and other.calls == [CAPTIONS]
    assert len([p for p in tmp_path.iterdir() if p.is_dir()]) == 2  # one folder per identity


def test_memory_layer_is_a_bounded_lru(tmp_path, spy):
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path, memory_items=2)
    cache.get_or_encode(CAPTIONS)
    assert len(cache) == 2
    cache.get_or_encode(CAPTIONS[:1])  # evicted from memory, read back from disk
    assert cache.disk_hits == 1 and len(spy.calls) == 1
    memory_only = TextFeatureCache(encoder=spy, cache_dir=None)
    memory_only.get_or_encode(CAPTIONS)
    memory_only.get_or_encode(CAPTIONS)
    assert memory_only.hits == 3 and memory_only.directory is None


def test_corrupt_entry_is_re_encoded_with_a_warning(tmp_path, spy, caplog):
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path, memory_items=0)
    expected = cache.get_or_encode(CAPTIONS[:1]).features
    path = cache.path(CAPTIONS[0])
    path.write_bytes(b"torn")
    with caplog.at_level("WARNING", logger="intermask.text.cache"):
        again = cache.get_or_encode(CAPTIONS[:1]).features
    assert str(path) in caplog.text and len(spy.calls) == 2
    assert torch.equal(again, expected)
    assert torch.load(path, weights_only=True)["caption"] == CAPTIONS[0]  # rewritten


def test_invalid_arguments(spy):
    with pytest.raises(ValueError, match="memory_items must be >= 0, got -1"):
        TextFeatureCache(encoder=spy, memory_items=-1)
    with pytest.raises(ValueError, match="batch_size must be >= 1, got 0"):
        TextFeatureCache(encoder=spy, batch_size=0)
    cache = TextFeatureCache(encoder=spy)
    with pytest.raises(TypeError, match="single string"):
        cache.get_or_encode("a person waves")
    with pytest.raises(ValueError, match="captions is empty"):
        cache.get_or_encode([])


def test_entries_of_the_batch_dependent_format_are_not_read(tmp_path, spy):
    """v1 entries (features computed in batches) sit under the identity's old hash: a v2 cache
    neither reads nor overwrites them."""
    from intermask.text.cache import CACHE_FORMAT, _sha256

    assert CACHE_FORMAT == "intermask-text-cache-v2"
    old_key = _sha256(spy.identity)[:16]  # v1: the identity's hash alone
    caption = CAPTIONS[0]
    key = _sha256(spy.identity, caption)  # the entry's own key did not change
    old = tmp_path / old_key / key[:2] / f"{key}.pt"
    old.parent.mkdir(parents=True)
    stale = torch.zeros(77, 64, dtype=torch.float16)
    payload = {"format": "intermask-text-cache-v1", "caption": caption, "tokens": stale}
    torch.save(payload | {"eot_index": 4}, old)
    cache = TextFeatureCache(encoder=spy, cache_dir=tmp_path)
    features = cache.get_or_encode([caption])
    assert spy.calls == [[caption]] and cache.disk_hits == 0
    assert cache.directory.name != old_key and cache.path(caption).is_file()
    assert not torch.equal(features.features[0].half(), stale)
    assert torch.equal(torch.load(old, weights_only=True)["tokens"], stale)  # left as it was
