"""The same results on a CUDA device as on the CPU, and a bf16 training run on one GPU.

Every test here is ``gpu``: `make test-gpu` runs them, and they are skipped without CUDA.
Matrix products run in full fp32 for the comparisons (TF32 off): the point is that the device
changes nothing but speed, not that TF32 is close to fp32.
"""

from __future__ import annotations

import pytest
import torch
from test_train_gen import _gen_config, vq_checkpoint  # noqa: F401 (a fixture)

from intermask.bench import build_models
from intermask.interm.decoding import generate
from intermask.metrics.fid import FID
from intermask.metrics.retrieval import MMDist, RPrecision
from intermask.train import train
from intermask.utils.optim import Muon

pytestmark = pytest.mark.gpu

CUDA = torch.device("cuda")


@pytest.fixture(autouse=True)
def full_fp32():
    """TF32 off for the comparisons, restored afterwards."""
    saved = torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32
    torch.backends.cuda.matmul.allow_tf32 = torch.backends.cudnn.allow_tf32 = False
    yield
    torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32 = saved


@pytest.fixture(scope="module")
def demo_models():
    """The demo-size VQ-VAE and Inter-M (random weights) on the CPU and a copy on the GPU."""
    vq, module = build_models("demo", torch.device("cpu"))
    vq.eval(), module.eval()
    gpu_vq, gpu_module = build_models("demo", torch.device("cpu"))
    gpu_vq.load_state_dict(vq.state_dict())
    gpu_module.load_state_dict(module.state_dict())
    return (vq, module), (gpu_vq.to(CUDA).eval(), gpu_module.to(CUDA).eval())


def _inputs(net, batch: int, steps: int, device: torch.device):
    generator = torch.Generator().manual_seed(3)
    shape = (batch, net.rows, steps)
    tokens = [torch.randint(0, net.codebook_size + 1, shape, generator=generator) for _ in "ab"]
    features = torch.randn(batch, 77, net.text_dim, generator=generator)
    eot = torch.tensor([12, 30, 5][:batch])
    lengths = torch.tensor([steps, steps - 7, steps - 3][:batch])
    from intermask.interm.model import TextFeatures
    from intermask.text.clip_encoder import padding_mask_from_eot

    text = TextFeatures(
        features.to(device), eot.to(device), padding_mask_from_eot(eot, 77).to(device)
    )
    return [t.to(device) for t in tokens], text, lengths.to(device)


def test_the_interm_forward_on_cuda_equals_the_cpu_one(demo_models):
    (_, cpu), (_, gpu) = demo_models
    with torch.no_grad():
        (a, b), text, lengths = _inputs(cpu.net, 3, 24, torch.device("cpu"))
        expected = cpu.net(a, b, text, lengths)
        (a, b), text, lengths = _inputs(gpu.net, 3, 24, CUDA)
        got = gpu.net(a, b, text, lengths)
    for ours, theirs in zip(got, expected, strict=True):
        assert ours.device.type == "cuda"
        torch.testing.assert_close(ours.cpu(), theirs, rtol=1e-4, atol=1e-4)


def test_a_seeded_generation_on_cuda_repeats_and_does_not_depend_on_the_batch(demo_models):
    _, (_, gpu) = demo_models
    (_, _), text, lengths = _inputs(gpu.net, 3, 24, CUDA)
    first = generate(gpu.net, text, lengths, iterations=6, seeds=[0, 1, 2])
    again = generate(gpu.net, text, lengths, iterations=6, seeds=[0, 1, 2])
    assert torch.equal(first, again)
    # sample 1 alone, with its own seed, gets the codes it got in the batch of three
    from intermask.interm.model import TextFeatures

    single = TextFeatures(text.features[1:2], text.eot_index[1:2], text.padding_mask[1:2])
    alone = generate(gpu.net, single, lengths[1:2], steps=24, iterations=6, seeds=[1])
    assert torch.equal(alone[0], first[1])
    # padding stays -1 and every other code is a real code
    steps = int(lengths[1])
    assert bool((first[1, ..., steps:] == -1).all())
    assert int(first[1, ..., :steps].min()) >= 0
    assert int(first[1, ..., :steps].max()) < gpu.net.codebook_size


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_decoding_through_cuda_graphs_gives_the_eager_tokens(demo_models, precision):
    """The graphed passes replay the eager kernels: the same tokens, in every decoding mode,
    from the second call on with no new capture."""
    from intermask.interm.graphs import GraphedForward

    _, (_, gpu) = demo_models
    (_, _), text, lengths = _inputs(gpu.net, 3, 24, CUDA)
    graphed = GraphedForward(gpu.net)
    settings = [
        {"iterations": 6},
        {"iterations": 3, "persons": "in_turn", "revisits": 1, "partner_scale": 1.0},
    ]
    with torch.autocast("cuda", dtype=torch.bfloat16, enabled=precision == "bf16"):
        for kwargs in settings:
            eager = generate(gpu.net, text, lengths, seeds=[0, 1, 2], **kwargs)
            for _ in range(2):
                assert torch.equal(
                    generate(gpu.net, text, lengths, seeds=[0, 1, 2], forward=graphed, **kwargs),
                    eager,
                )
    assert graphed.failure is None
    # one graph per batch shape: guided (2B) and partner-guided (3B)
    assert graphed.captured == 2


def test_masked_attention_on_cuda_skips_the_cudnn_kernel(monkeypatch):
    """With a mask, SDPA runs without cuDNN's kernel (slower with masks: docs/performance.md) and
    its bf16 result is the CPU's fp32 one within bf16 rounding; an unmasked call keeps PyTorch's
    choice, and the global switch is as it was afterwards."""
    from intermask.utils import layers

    torch.manual_seed(0)
    attention = layers.Attention(width=128, heads=2, dropout=0.0).eval()
    x = torch.randn(6, 40, 128)
    mask = torch.rand(6, 1, 1, 40) > 0.4
    mask[:, ..., 0] = True  # every query has a key
    with torch.no_grad():
        expected = attention(x, mask=mask)  # CPU, fp32

    real, seen = layers.F.scaled_dot_product_attention, []

    def spy(*args, **kwargs):
        seen.append((kwargs["attn_mask"] is not None, torch.backends.cuda.cudnn_sdp_enabled()))
        return real(*args, **kwargs)

    monkeypatch.setattr(layers.F, "scaled_dot_product_attention", spy)
    gpu = attention.to(CUDA)
    with torch.no_grad(), torch.autocast("cuda", dtype=torch.bfloat16):
        masked = gpu(x.to(CUDA), mask=mask.to(CUDA))
        gpu(x.to(CUDA))
    before = torch.backends.cuda.cudnn_sdp_enabled()
    assert seen == [(True, False), (False, before)]
    assert masked.dtype == torch.bfloat16
    torch.testing.assert_close(masked.float().cpu(), expected, rtol=0.0, atol=0.03)


def test_the_vq_round_trip_on_cuda_equals_the_cpu_one(demo_models):
    (cpu, _), (gpu, _) = demo_models
    generator = torch.Generator().manual_seed(5)
    features = torch.randn(2, 64, *cpu.view.feature_shape, generator=generator)
    with torch.no_grad():
        codes = cpu.encode(features, torch.tensor([64, 40]))
        gpu_codes = gpu.encode(features.to(CUDA), torch.tensor([64, 40], device=CUDA))
        assert torch.equal(gpu_codes.cpu(), codes)
        decoded = cpu.decode(codes)
        gpu_decoded = gpu.decode(gpu_codes)
    torch.testing.assert_close(gpu_decoded.cpu(), decoded, rtol=1e-4, atol=1e-4)


def test_the_metrics_on_cuda_equal_the_cpu_ones():
    generator = torch.Generator().manual_seed(7)
    real, fake = torch.randn(2, 96, 16, generator=generator)
    text = fake + 0.5 * torch.randn(96, 16, generator=generator)
    values = []  # the CPU's, then the GPU's
    for device in (torch.device("cpu"), CUDA):
        fid = FID().to(device)
        fid.update(real.to(device), real=True)
        fid.update(fake.to(device), real=False)
        top, mm = RPrecision(top_k=3).to(device), MMDist().to(device)
        for group in range(3):  # the protocol's groups of 32
            rows = slice(32 * group, 32 * group + 32)
            top.update(text[rows].to(device), fake[rows].to(device))
            mm.update(text[rows].to(device), fake[rows].to(device))
        values.append([float(fid.compute()), *top.compute().tolist(), float(mm.compute())])
    assert values[1] == pytest.approx(values[0], rel=1e-9, abs=1e-9)
    assert values[0][0] > 0.5  # two independent draws of 96 points in 16-d are far apart
    assert 0.5 < values[0][3] <= 1.0  # the texts are noisy copies of their motions


def test_muon_steps_on_cuda_equal_the_cpu_ones():
    """Newton-Schulz, the batched shapes and the AdamW groups give the CPU's weights on CUDA."""
    generator = torch.Generator().manual_seed(0)
    shapes = [(64, 32), (64, 32), (32, 64), (16, 8, 3, 3), (64,)]  # two of one shape: one batch
    start = [torch.randn(shape, generator=generator) for shape in shapes]
    grads = [[torch.randn(shape, generator=generator) for shape in shapes] for _ in range(3)]
    weights = {}
    for device in ("cpu", "cuda"):
        params = [torch.nn.Parameter(w.clone().to(device)) for w in start]
        optimizer = Muon(
            [{"params": params[:4], "muon": True}, {"params": params[4:], "muon": False}],
            lr=0.02,
            weight_decay=0.1,
        )
        for step in grads:
            for param, grad in zip(params, step, strict=True):
                param.grad = grad.to(device)
            optimizer.step()
        weights[device] = [p.detach().cpu() for p in params]
    for before, cpu, cuda in zip(start, weights["cpu"], weights["cuda"], strict=True):
        assert (cpu - before).abs().max() > 1e-3  # three steps moved every weight
        torch.testing.assert_close(cuda, cpu, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("optimizer", ["torch.optim.AdamW", "intermask.utils.optim.Muon"])
def test_train_gen_runs_on_one_gpu_in_bf16(
    synthetic_interhuman_root,
    vq_checkpoint,  # noqa: F811
    tmp_path,
    optimizer,
):
    extra = (f"model.optimizer._target_={optimizer}",)
    cfg = _gen_config(synthetic_interhuman_root, vq_checkpoint, tmp_path, extra=extra)
    from omegaconf import open_dict

    with open_dict(cfg):
        cfg.trainer.accelerator = "gpu"
        cfg.trainer.devices = 1
        cfg.trainer.precision = "bf16-mixed"
    metrics = train(cfg)
    loss = torch.tensor(metrics["val/loss"])
    assert torch.isfinite(loss) and 0.0 < float(loss) < 10.0
    assert 2.5 < metrics["val/fully_masked_ce"] < 4.5  # two steps: near ln(32 codes), as on CPU
