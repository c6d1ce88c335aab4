"""InterMask's release, converted by ``intermask convert-reference``'s code, gives what the
authors' code gave (tests/parity/fixtures/intermask_models.pt, written by
``tools/parity/intermask_models.py --write-fixture`` against gohar-malik/InterMask).

The fixture holds the recipe of the release's weights, the inputs and the authors' outputs; the
release is rebuilt on disk here and converted as a user's would be, so a change anywhere on that
path (conversion, opt.txt mapping, the networks, the reference switches, seeded decoding) that
breaks parity fails here, without the authors' code present.
"""

from __future__ import annotations

import pytest
import torch
from fixtures_io import load_fixture
from intermask_release import (
    CASES,
    _generator_options,
    convert_case,
    our_decode,
    our_features,
    our_logits,
    text_features,
)

from intermask.interm.decoding import generate
from intermask.release_options import UnsupportedOption, generator_overrides, vq_overrides
from intermask.vq.convolutions import SkeletonGraphLayer

LOGITS, DECODED = 1e-4, 1e-5  # the tolerances (measured: 2.9e-6 and 6e-8)


@pytest.fixture(scope="module")
def fixture() -> dict:
    torch.set_num_threads(min(torch.get_num_threads(), 2))
    return load_fixture("intermask_models")


@pytest.mark.parametrize("name", ["vq_interx", "vq_interhuman"])
def test_converted_tokenizers_encode_and_decode_as_the_authors(fixture, name, tmp_path):
    stored = fixture[name]
    ours = convert_case(name, fixture, tmp_path)
    motion, codes = stored["inputs"]["motion"], stored["inputs"]["codes"]
    graph_layers = [m for m in ours.modules() if isinstance(m, SkeletonGraphLayer)]
    assert len(graph_layers) == (4 if name == "vq_interhuman" else 0)
    # the stored outputs are the authors' module on a batch of two: with graph ends, only frame
    # 0 of the batch's first sequence aggregates there ("batch_first")
    default = _encode_decode(ours, motion, codes)
    for layer in graph_layers:
        assert layer.frames == "first"  # the conversion's: each sequence as if passed alone
        layer.frames = "batch_first"
    latent, decoded = _encode_decode(ours, motion, codes)
    torch.testing.assert_close(latent, stored["latent"].reshape(latent.shape), rtol=0, atol=DECODED)
    torch.testing.assert_close(
        decoded, stored["decoded"].reshape(decoded.shape), rtol=0, atol=DECODED
    )
    assert float(stored["decoded"].abs().max()) > 0.5  # a tolerance that means something
    # the default equals the authors' module given each sequence alone (the first: stored)
    for sample in range(motion.shape[0]):
        alone = _encode_decode(ours, motion[sample : sample + 1], codes[sample : sample + 1])
        for mine, theirs in zip(default, alone, strict=True):
            torch.testing.assert_close(mine[sample : sample + 1], theirs, rtol=0, atol=DECODED)
    if graph_layers:  # and the two readings differ beyond the first sequence
        assert float((default[1][1] - decoded[1]).abs().max()) > 1e-2


def _encode_decode(vq, motion, codes) -> tuple[torch.Tensor, torch.Tensor]:
    with torch.no_grad():
        return vq.encoder(vq.view.to_joints(motion)), our_decode(vq, codes)


@pytest.mark.parametrize("name", ["generator", "generator_8_heads"])
def test_converted_generators_give_the_authors_logits_and_decodings(fixture, name, tmp_path):
    stored = fixture[name]
    ours = convert_case(name, fixture, tmp_path)
    assert ours.blocks[0].self_attention.attention.heads == int(CASES[name]["options"]["n_heads"])
    features = our_features(text_features(fixture["seed"]), stored["inputs"]["captions"])
    for drop, theirs in ((False, stored["logits"]), (True, stored["null_logits"])):
        mine, expected = our_logits(ours, features, stored["inputs"], drop, theirs)
        torch.testing.assert_close(mine, expected, rtol=0, atol=LOGITS)
    assert float(stored["logits"].abs().max()) > 1.0
    lengths = stored["inputs"]["lengths"]
    for seed, theirs in stored["decoded_tokens"].items():
        mine = generate(ours, features, lengths, iterations=10, cfg_scale=2.0, top_k_ratio=0.1,
                        seeds=[seed] * len(lengths), schedule="reference", noise="reference")  # fmt: skip
        assert torch.equal(mine.flatten(1), theirs), f"seed {seed}"


def test_every_architecture_option_is_mapped_or_refused_by_name():
    options = _generator_options(8)
    mapped = generator_overrides(options, source="opt.txt")
    assert mapped == {"model.net.width": 96, "model.net.heads": 8, "model.net.depth": 2,
                      "model.net.ff": 128, "model.net.dropout": 0.2,
                      "model.condition_drop": 0.1}  # fmt: skip
    with pytest.raises(
        UnsupportedOption, match=r"n_heads: 7 \(7 heads do not divide latent_dim 96\)"
    ):
        generator_overrides({**options, "n_heads": "7"}, source="opt.txt")
    with pytest.raises(
        UnsupportedOption, match=r"force_mask: True \(this framework builds only False\)"
    ):
        generator_overrides({**options, "force_mask": "True"}, source="opt.txt")
    vq = CASES["vq_interx"]["options"]
    assert vq_overrides(vq, source="opt.txt")["model.net.encoder.dilations"] == [3, 1]
    with pytest.raises(
        UnsupportedOption, match=r"vq_act: gelu \(this framework builds only relu\)"
    ):
        vq_overrides({**vq, "vq_act": "gelu"}, source="opt.txt")
    with pytest.raises(UnsupportedOption, match=r"code_dim: 64 \(.*equal to width \(32\)\)"):
        vq_overrides({**vq, "code_dim": "64"}, source="opt.txt")
    with pytest.raises(UnsupportedOption, match=r"wandb: True \(not an option of the authors'"):
        vq_overrides({**vq, "wandb": "True"}, source="opt.txt")
    assert "model.net.quantizer.codebook_size" in vq_overrides(
        {**vq, "wandb": "True"}, source="opt.txt", ignore=("wandb",)
    )


def test_an_opt_txt_that_contradicts_the_weights_is_refused_naming_the_release_key(
    fixture, tmp_path
):
    """The release's weights are 96 wide; an opt.txt claiming 120 cannot be built from them."""
    wide = {**_generator_options(6), "latent_dim": "120"}
    with pytest.raises(ValueError) as refused:
        convert_case("generator", fixture, tmp_path, options=wide)
    message = str(refused.value)
    assert "the reference generator does not map onto this framework's" in message
    assert "token_emb.weight" not in message  # the code width still agrees
    assert "input_process.poseEmbedding.weight (-> token_projection.weight): release (96, 32)" \
        " vs ours (120, 32)" in message  # fmt: skip
    assert not (tmp_path / "out").exists()
