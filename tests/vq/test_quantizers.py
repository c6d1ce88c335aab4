import functools

import pytest
import torch
from gloo import run_on_processes

from intermask.vq.quantizers import EMAQuantizer, ResidualQuantizer


def test_first_training_batch_initialises_the_codebook_from_encoder_outputs():
    torch.manual_seed(0)
    quantizer = EMAQuantizer(codebook_size=8, dim=4).train()
    x = torch.randn(2, 4, 2, 3)  # 12 vectors
    out = quantizer(x)
    vectors = x.permute(0, 2, 3, 1).reshape(-1, 4)
    # every code is one of the batch's vectors, nudged by one EMA step toward its assigned mean
    assert bool(quantizer.initialized)
    assert out.indices.shape == (2, 2, 3) and out.quantized.shape == x.shape
    distances = torch.cdist(quantizer.codebook, vectors).min(dim=1).values
    assert distances.max() < 1.0


def test_ema_update_moves_codes_toward_the_mean_of_their_vectors():
    quantizer = EMAQuantizer(codebook_size=2, dim=2, decay=0.5, reset_threshold=0.0).train()
    quantizer.codebook.copy_(torch.tensor([[0.0, 0.0], [10.0, 10.0]]))
    quantizer.ema_sum.copy_(quantizer.codebook)
    quantizer.ema_count.fill_(1.0)
    quantizer.initialized.fill_(True)
    x = torch.tensor([[1.0, 1.0], [3.0, 3.0], [9.0, 9.0]]).T.reshape(1, 2, 1, 3)
    quantizer(x)
    # code 0: count 0.5*1 + 0.5*2 = 1.5, sum 0.5*0 + 0.5*(4, 4) = (2, 2)
    # code 1: count 0.5*1 + 0.5*1 = 1.0, sum 0.5*(10, 10) + 0.5*(9, 9) = (9.5, 9.5)
    torch.testing.assert_close(quantizer.ema_count, torch.tensor([1.5, 1.0]))
    torch.testing.assert_close(
        quantizer.codebook, torch.tensor([[2 / 1.5, 2 / 1.5], [9.5, 9.5]]), atol=1e-4, rtol=0
    )


def _one_used_code_of_three(quantizer: EMAQuantizer) -> torch.Tensor:
    """Codes at the origin and far away, counts 1; -> a batch of 4 vectors all nearest code 0."""
    quantizer.codebook.copy_(torch.tensor([[0.0, 0.0], [100.0, 100.0], [-100.0, 100.0]]))
    quantizer.ema_sum.copy_(quantizer.codebook)
    quantizer.ema_count.fill_(1.0)
    quantizer.initialized.fill_(True)
    return torch.tensor([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.0, -0.1]]).T.reshape(1, 2, 1, 4)


def test_dead_codes_are_reset_to_current_encoder_outputs():
    quantizer = EMAQuantizer(codebook_size=3, dim=2, decay=0.9, reset_threshold=1.0).train()
    x = _one_used_code_of_three(quantizer)
    out = quantizer(x)
    # codes 1 and 2 got nothing: count 0.9 < 1 -> replaced by batch vectors, count back to 1
    assert out.dead_codes == 2
    vectors = x.permute(0, 2, 3, 1).reshape(-1, 2)
    for code in (1, 2):
        assert torch.isclose(
            torch.cdist(quantizer.codebook[code : code + 1], vectors), torch.tensor(0.0)
        ).any()
    torch.testing.assert_close(quantizer.ema_count[1:], torch.ones(2))


def test_the_reference_reset_keeps_raw_statistics_and_overwrites_unused_codes():
    """reset="reference": codes are raw EMA means (no smoothing); an unused code is replaced by
    a batch vector while its count stays below the threshold and its sum is kept."""
    quantizer = EMAQuantizer(codebook_size=3, dim=2, decay=0.9, reset="reference").train()
    x = _one_used_code_of_three(quantizer)
    out = quantizer(x)
    assert out.dead_codes == 2
    # code 0: count 0.9 + 0.1 * 4 = 1.3, sum 0.9 * 0 + 0.1 * 0 = 0 -> mean exactly 0
    torch.testing.assert_close(quantizer.ema_count, torch.tensor([1.3, 0.9, 0.9]))
    assert torch.equal(quantizer.codebook[0], torch.zeros(2))
    torch.testing.assert_close(
        quantizer.ema_sum[1:], 0.9 * torch.tensor([[100.0, 100.0], [-100.0, 100.0]])
    )
    vectors = x.permute(0, 2, 3, 1).reshape(-1, 2)
    for code in (1, 2):
        assert (torch.cdist(quantizer.codebook[code : code + 1], vectors) == 0).any()
    # the default restart rule on the same step: counts back to 1, sums reset
    restart = EMAQuantizer(codebook_size=3, dim=2, decay=0.9).train()
    restart.load_state_dict(
        {
            **quantizer.state_dict(),
            "ema_count": torch.ones(3),
            "ema_sum": torch.tensor([[0.0, 0.0], [100.0, 100.0], [-100.0, 100.0]]),
        }
    )
    restart(x)
    torch.testing.assert_close(restart.ema_count[1:], torch.ones(2))


def test_the_farthest_reset_gives_dead_codes_the_worst_served_vectors_in_order():
    """reset="farthest": the dead codes (1 and 2, in index order) restart from the batch vectors
    farthest from the code they were assigned, the worst first; code 0 is an EMA mean as with
    "restart", and the counts go back to 1."""
    quantizer = EMAQuantizer(codebook_size=3, dim=2, decay=0.9, reset="farthest").train()
    x = _one_used_code_of_three(quantizer)
    x[:, :, 0, 1] = torch.tensor([0.0, 3.0])  # the worst served (9 from code 0)
    x[:, :, 0, 3] = torch.tensor([2.0, 0.0])  # the next (4)
    out = quantizer(x)
    assert out.dead_codes == 2
    torch.testing.assert_close(quantizer.codebook[1:], torch.tensor([[0.0, 3.0], [2.0, 0.0]]))
    torch.testing.assert_close(quantizer.ema_sum[1:], quantizer.codebook[1:])
    torch.testing.assert_close(quantizer.ema_count, torch.tensor([1.3, 1.0, 1.0]))
    # the same step under "restart" draws the replacements at random from the batch
    restart = EMAQuantizer(codebook_size=3, dim=2, decay=0.9).train()
    y = _one_used_code_of_three(restart)
    y[:, :, 0, 1], y[:, :, 0, 3] = torch.tensor([0.0, 3.0]), torch.tensor([2.0, 0.0])
    torch.testing.assert_close(restart(y).quantized, out.quantized)  # same codes used this step
    torch.testing.assert_close(restart.codebook[0], quantizer.codebook[0])


def test_the_farthest_reset_cycles_when_codes_outnumber_vectors_and_skips_non_finite_rows():
    quantizer = EMAQuantizer(codebook_size=4, dim=1, decay=0.5, reset="farthest").train()
    quantizer.codebook.copy_(torch.tensor([[0.0], [50.0], [60.0], [70.0]]))
    quantizer.ema_sum.copy_(quantizer.codebook)
    quantizer.ema_count.fill_(1.0)
    quantizer.initialized.fill_(True)
    x = torch.tensor([1.0, 3.0, float("nan")]).reshape(1, 1, 1, 3)
    out = quantizer(x)
    # codes 1-3 die (count 0.5): 3.0 (error 9), then 1.0 (1), then 3.0 again; the NaN row never
    assert out.dead_codes == 3
    torch.testing.assert_close(quantizer.codebook[1:, 0], torch.tensor([3.0, 1.0, 3.0]))


def _farthest_step(x: torch.Tensor) -> EMAQuantizer:
    """A farthest-reset quantizer after one step on ``x``: 8 codes, all but code 0 far away."""
    quantizer = EMAQuantizer(codebook_size=8, dim=2, decay=0.9, reset="farthest").train()
    codebook = torch.cat((torch.zeros(1, 2), torch.full((7, 2), 100.0)))
    quantizer.codebook.copy_(codebook)
    quantizer.ema_sum.copy_(codebook)
    quantizer.ema_count.fill_(1.0)
    quantizer.initialized.fill_(True)
    quantizer(x)
    return quantizer


def _farthest_worker(rank: int, world: int, *, out_dir: str) -> None:
    x = torch.randn(2, 2, 2, 3, generator=torch.Generator().manual_seed(0))
    quantizer = _farthest_step(x[rank : rank + 1])  # each rank holds half the global batch
    torch.save(quantizer.codebook, f"{out_dir}/rank{rank}.pt")


def test_the_farthest_reset_on_two_ranks_equals_one_process(tmp_path):
    run_on_processes(functools.partial(_farthest_worker, out_dir=str(tmp_path)), world=2)
    x = torch.randn(2, 2, 2, 3, generator=torch.Generator().manual_seed(0))
    one = _farthest_step(x).codebook
    vectors = x.permute(0, 2, 3, 1).reshape(-1, 2)
    errors = vectors.pow(2).sum(-1)  # every vector was assigned code 0, at the origin
    torch.testing.assert_close(one[1:], vectors[errors.argsort(descending=True)[:7]])
    for rank in range(2):
        torch.testing.assert_close(torch.load(tmp_path / f"rank{rank}.pt", weights_only=True), one)


def test_eval_mode_picks_the_nearest_code_and_leaves_the_codebook_alone():
    quantizer = EMAQuantizer(codebook_size=2, dim=1, stochastic_temperature=0.5).eval()
    quantizer.codebook.copy_(torch.tensor([[0.0], [1.0]]))
    before = quantizer.codebook.clone()
    out = quantizer(torch.tensor([0.2, 0.9, 0.6, -3.0]).reshape(1, 1, 1, 4))
    assert out.indices.flatten().tolist() == [0, 1, 1, 0]
    assert torch.equal(quantizer.codebook, before)


def test_straight_through_gradient_reaches_the_encoder_output():
    quantizer = ResidualQuantizer(num_quantizers=3, codebook_size=16, dim=4).train()
    x = torch.randn(2, 4, 5, 4, requires_grad=True)
    out = quantizer(x)
    (out.quantized * torch.arange(4.0).reshape(1, 4, 1, 1)).sum().backward()
    torch.testing.assert_close(x.grad, torch.arange(4.0).reshape(1, 4, 1, 1).expand_as(x))


def test_six_residual_layers_reconstruct_better_than_one():
    torch.manual_seed(0)
    x = torch.randn(16, 32, 5, 8)
    errors = {}
    for layers in (1, 6):
        quantizer = ResidualQuantizer(num_quantizers=layers, codebook_size=64, dim=32).train()
        for _ in range(10):
            quantizer(x)
        out = quantizer.eval()(x)
        errors[layers] = (out.quantized - x).pow(2).mean().item()
        torch.testing.assert_close(quantizer.lookup(out.indices), out.quantized)
    assert errors[6] < 0.5 * errors[1]


def test_quantization_dropout_keeps_a_prefix_of_layers():
    torch.manual_seed(3)
    quantizer = ResidualQuantizer(
        num_quantizers=4, codebook_size=8, dim=4, dropout_prob=1.0
    ).train()
    kept_counts = set()
    for _ in range(20):
        indices = quantizer(torch.randn(2, 4, 1, 4)).indices
        used = (indices[:, :, 0, 0] >= 0)[0]
        kept = int(used.sum())
        assert used[:kept].all() and not used[kept:].any()  # a prefix, layer 0 always kept
        kept_counts.add(kept)
    assert kept_counts > {1} and len(kept_counts) >= 3


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(decay=1.0), r"decay must be in \(0, 1\), got 1.0"),
        (
            dict(stochastic_temperature=0.0),
            "stochastic_temperature must be positive or None, got 0.0",
        ),
        (
            dict(reset="x"),
            r"reset must be one of \('restart', 'reference', 'farthest'\), got 'x'",
        ),
    ],
)
def test_invalid_options_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        EMAQuantizer(codebook_size=4, dim=2, **kwargs)


def test_quantizer_runs_in_float32_under_bf16_autocast():
    torch.manual_seed(0)
    quantizer = ResidualQuantizer(num_quantizers=2, codebook_size=64, dim=16).train()
    x = torch.randn(4, 16, 5, 8)
    quantizer(x)  # initialise
    quantizer.eval()
    reference = quantizer(x)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = quantizer(x.to(torch.bfloat16))
    assert out.quantized.dtype == torch.float32
    # bf16 input rounding may move a few borderline vectors, never most of them
    assert (out.indices == reference.indices).float().mean() > 0.9
