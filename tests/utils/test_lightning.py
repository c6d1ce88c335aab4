"""The shared LightningModule helpers: when step logs are written, and what the optimizer gets."""

from types import SimpleNamespace

import lightning as L
import pytest
import torch
from torch import nn

from intermask.utils.lightning import ScheduledModule, writes_step_logs


def _module_at(step: int, every: int, should_stop: bool = False) -> L.LightningModule:
    module = L.LightningModule()
    module._trainer = SimpleNamespace(
        global_step=step, log_every_n_steps=every, should_stop=should_stop
    )
    return module


def test_step_logs_are_written_every_n_optimizer_steps() -> None:
    written = [step for step in range(30) if writes_step_logs(_module_at(step, every=10))]
    # Lightning writes after the 10th, 20th, 30th step: global_step 9, 19, 29 during training_step
    assert written == [9, 19, 29]


def test_step_logs_on_stop_never_when_disabled_always_outside_a_trainer() -> None:
    assert writes_step_logs(_module_at(3, every=10, should_stop=True))
    assert not writes_step_logs(_module_at(9, every=0))
    assert writes_step_logs(L.LightningModule())


class _PartlyFrozen(ScheduledModule):
    def __init__(self) -> None:
        super().__init__()
        self.save_hyperparameters(
            {"warmup_fraction": 0.5, "lr_milestones": [0.75], "lr_gamma": 0.1}
        )
        self.frozen, self.trained = nn.Linear(2, 2), nn.Linear(2, 2)
        self.frozen.requires_grad_(False)
        self.optimizer_factory = lambda params: torch.optim.SGD(params, lr=1.0)

    def optimized_parameters(self) -> list[nn.Parameter]:
        return [p for p in self.parameters() if p.requires_grad]


def test_scheduled_module_optimizes_what_it_names_on_the_warmup_schedule() -> None:
    module = _PartlyFrozen()
    module._trainer = SimpleNamespace(estimated_stepping_batches=4)
    config = module.configure_optimizers()
    optimizer, scheduler = config["optimizer"], config["lr_scheduler"]["scheduler"]
    optimized = {id(p) for group in optimizer.param_groups for p in group["params"]}
    assert optimized == {id(p) for p in module.trained.parameters()}
    assert config["lr_scheduler"]["interval"] == "step"
    rates = []
    for _ in range(4):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        scheduler.step()
    assert rates == pytest.approx([0.5, 1.0, 1.0, 0.1])  # 2 warm-up steps, x0.1 from step 3


def test_attention_mask_hides_keys_and_context_defaults_to_the_queries() -> None:
    from intermask.utils.layers import Attention

    torch.manual_seed(0)
    attention = Attention(width=8, heads=2, dropout=0.0).eval()
    x, context = torch.randn(2, 3, 8), torch.randn(2, 4, 8)
    mask = torch.tensor([True, True, False, True])[None, None, None, :]
    changed = context.clone()
    changed[:, 2] += 10.0  # a hidden key/value: must not matter
    out = attention(x, context, mask)
    assert out.shape == (2, 3, 8)
    torch.testing.assert_close(out, attention(x, changed, mask))
    assert not torch.allclose(attention(x, context), attention(x, changed))
    torch.testing.assert_close(attention(x), attention(x, x))
    with pytest.raises(ValueError, match="width 6 is not divisible by 4 heads"):
        Attention(width=6, heads=4, dropout=0.0)


def test_masked_attention_on_the_cpu_leaves_the_kernel_choice_to_pytorch(monkeypatch) -> None:
    """The kernel switch for masked attention is a CUDA one (docs/performance.md): on the CPU a
    masked call sees PyTorch's own backend flags and gives plain SDPA's output, bit for bit."""
    import torch.nn.functional as F

    from intermask.utils import layers

    flags = (
        torch.backends.cuda.cudnn_sdp_enabled(),
        torch.backends.cuda.mem_efficient_sdp_enabled(),
    )
    real, seen = F.scaled_dot_product_attention, []

    def spy(*args, **kwargs):
        seen.append(
            (
                torch.backends.cuda.cudnn_sdp_enabled(),
                torch.backends.cuda.mem_efficient_sdp_enabled(),
            )
        )
        return real(*args, **kwargs)

    torch.manual_seed(0)
    attention = layers.Attention(width=8, heads=2, dropout=0.0).eval()
    x, mask = torch.randn(2, 5, 8), torch.tensor([True, False, True, True, False])
    monkeypatch.setattr(layers.F, "scaled_dot_product_attention", spy)
    out = attention(x, mask=mask[None, None, None, :])
    assert seen == [flags]
    q = attention.query(x).reshape(2, 5, 2, 4).transpose(1, 2)
    k, v = attention.key_value(x).reshape(2, 5, 2, 2, 4).permute(2, 0, 3, 1, 4)
    plain = real(q, k, v, attn_mask=mask[None, None, None, :])
    assert torch.equal(out, attention.out(plain.transpose(1, 2).reshape(2, 5, 8)))
