"""`intermask convert-reference`: a release laid out as the authors publish it (model/<which>.tar
beside opt.txt) becomes two run folders that load_generator accepts, with the reference
switches on; bad releases are refused by name before anything is written."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from intermask.cli import main


def _layouts():
    """The reference key layouts written out in tests/interm and tests/vq (loaded by path: the
    test folders are not packages)."""
    import importlib.util

    modules = {}
    for name, path in (
        ("generator", "interm/test_reference_generator.py"),
        ("vq", "vq/test_reference_vq.py"),
    ):
        spec = importlib.util.spec_from_file_location(
            f"reference_layout_{name}", Path(__file__).parent / path
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        modules[name] = module
    return modules["generator"].reference_layout(), modules["vq"].reference_interx_layout()


def _release(root: Path, name: str, entry: str, layout: dict, options: dict) -> Path:
    folder = root / name
    (folder / "model").mkdir(parents=True)
    generator = torch.Generator().manual_seed(len(name))
    state = {k: torch.randn(s, generator=generator) * 0.02 for k, s in layout.items()}
    if "position_enc.positional_encoding.inv_freq" in state:  # a computed buffer, not a weight
        channels = 384 // 2
        frequencies = 1.0 / (10000 ** (torch.arange(0, channels, 2).float() / channels))
        state["position_enc.positional_encoding.inv_freq"] = frequencies
    torch.save({entry: state, "ep": 3, "total_it": 10}, folder / "model" / "net_best_fid.tar")
    lines = ["------------ Options -------------"]
    lines += [f"{k}: {v}" for k, v in sorted(options.items())] + [
        "-------------- End ----------------"
    ]
    (folder / "opt.txt").write_text("\n".join(lines) + "\n")
    return folder / "model" / "net_best_fid.tar"


@pytest.mark.slow
def test_a_release_becomes_runs_that_load_with_the_reference_switches(tmp_path, capsys):
    from intermask.interm.load import load_generator

    generator_layout, vq_layout = _layouts()
    vq = _release(tmp_path, "vq_release", "vq_model", vq_layout,
                  {"dataset_name": "interx", "nb_code": 1024})  # fmt: skip
    layout = {k: s for k, s in generator_layout.items() if not k.startswith("clip_")}
    generator = _release(tmp_path, "trans_release", "t2m_transformer", layout,
                         {"dataset_name": "interx", "latent_dim": 384})  # fmt: skip
    out = tmp_path / "converted"
    code = main(
        ["convert-reference", "--vq", str(vq), "--generator", str(generator), "--out", str(out)]
    )
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert f"generator run: {out / 'gen'}" in printed.out
    from omegaconf import OmegaConf

    config = OmegaConf.load(out / "gen" / "config.yaml")
    assert config.text.encoder.pretrained == "openai"  # the paper's CLIP tower
    config.text.encoder.pretrained = None  # offline here: a random tower of the same shape
    OmegaConf.save(config, out / "gen" / "config.yaml")
    loaded = load_generator(out / "gen")
    net = loaded.net
    assert (net.text_attends_padding, net.blocks[0].cross_context_quirk) == (True, True)
    reference = torch.load(generator, weights_only=True)["t2m_transformer"]
    packed = reference["Transformer.blocks.2.self_attn.attention.in_proj_weight"]
    torch.testing.assert_close(net.blocks[2].self_attention.attention.query.weight, packed[:384])
    codebook = torch.load(vq, weights_only=True)["vq_model"]["quantizer.layers.0.codebook"]
    torch.testing.assert_close(loaded.vq.quantizer.layers[0].codebook, codebook)
    # a second conversion into the same folder is refused, nothing overwritten
    before = (out / "vq" / "checkpoints" / "last.ckpt").stat().st_mtime_ns
    assert main(["convert-reference", "--vq", str(vq), "--out", str(out)]) == 2
    assert "exists: choose another --out (nothing was overwritten)" in capsys.readouterr().err
    assert (out / "vq" / "checkpoints" / "last.ckpt").stat().st_mtime_ns == before


def test_bad_releases_are_refused_by_name(tmp_path, capsys):
    layout = {"decoder.model.0.weight": (4, 4, 3, 3)}
    vq = _release(tmp_path, "a", "optimizer", layout, {"dataset_name": "interx"})
    assert main(["convert-reference", "--vq", str(vq), "--out", str(tmp_path / "o1")]) == 2
    assert (
        "not a reference VQ-VAE checkpoint (no vq_model or net; found ['ep', 'optimizer', 'total_it'])"
        in capsys.readouterr().err
    )
    (tmp_path / "a" / "opt.txt").unlink()
    assert main(["convert-reference", "--vq", str(vq), "--out", str(tmp_path / "o2")]) == 2
    assert "no opt.txt beside it" in capsys.readouterr().err
    graph = {"encoder.gcn_layer1.lin.weight": (12, 12), "quantizer.layers.0.codebook": (1024, 512)}
    vq = _release(tmp_path, "b", "vq_model", graph, {"dataset_name": "interhuman"})
    assert main(["convert-reference", "--vq", str(vq), "--out", str(tmp_path / "o3")]) == 2
    err = capsys.readouterr().err
    assert "this tokenizer normalizes its features: pass the release's statistics" in err
    assert main(["convert-reference", "--vq", str(vq), "--mean", "m.npy", "--out", "o4"]) == 2
    assert "--mean and --std go together" in capsys.readouterr().err
    assert not (tmp_path / "o3").exists()
