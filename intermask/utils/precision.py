"""``trainer.precision: auto``: the precision that is fast and safe on the hardware at hand.

bf16 autocast pays only where the hardware has bf16 units. On CUDA that is Ampere and newer; on a
CPU it is AVX512-BF16 or AMX (x86) or the bf16 extensions (ARM). Without them PyTorch emulates
bf16 and is far slower than fp32: on an AVX2-only AMD EPYC a 512x512 bf16 matmul took ~30x and a
bf16 conv ~14x the fp32 time. ``torch.backends.cpu.get_cpu_capability()`` only names the vector
width ("AVX2", "AVX512"; an AVX512 CPU need not have bf16), so the decision reads the feature
flags of ``torch.cpu.get_capabilities()``.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

AUTO = "auto"
BF16 = "bf16-mixed"
FP32 = "32-true"
# the command-line spelling (`make bench`, `intermask generate --precision`) -> the Trainer's
OPTIONS = {"32": FP32, "bf16": BF16, "auto": AUTO}
# torch.cpu.get_capabilities() flags that mean native bf16 arithmetic (x86, then ARM)
NATIVE_BF16_FLAGS = ("avx512_bf16", "amx_bf16", "bf16", "sve_bf16")


class PrecisionChoice(NamedTuple):
    """The precision given to the Trainer and why (``reason`` is what the log prints)."""

    requested: str
    precision: str
    reason: str

    def as_record(self) -> dict[str, str]:
        return self._asdict()


def cpu_bf16_flags() -> list[str]:
    """The native-bf16 feature flags this CPU reports (empty when it has none)."""
    capabilities = getattr(torch.cpu, "get_capabilities", None)
    if capabilities is not None:
        flags = capabilities()
        return [name for name in NATIVE_BF16_FLAGS if flags.get(name) is True]
    # older torch: the private probes behind get_capabilities (x86 only)
    found = []
    if torch.cpu._is_avx512_bf16_supported():
        found.append("avx512_bf16")
    if torch.cpu._is_amx_tile_supported():
        found.append("amx_bf16")
    return found


def _uses_cuda(accelerator: str) -> bool:
    if accelerator in ("gpu", "cuda"):
        return True
    return accelerator == "auto" and torch.cuda.is_available()


def resolve_precision(requested: str | int, accelerator: str = "auto") -> PrecisionChoice:
    """``requested`` (a Trainer precision or ``auto``) -> the precision to train with.

    ``auto``: CUDA with bf16 -> bf16-mixed; CUDA without -> 32-true (fp16 would need loss scaling
    the VQ losses were not tuned for); CPU with native bf16 -> bf16-mixed; any other CPU or
    accelerator -> 32-true. Any explicit value is returned as given.
    """
    requested = str(requested)
    if requested != AUTO:
        return PrecisionChoice(requested, requested, "set explicitly")
    if _uses_cuda(accelerator):
        if torch.cuda.is_bf16_supported():
            return PrecisionChoice(AUTO, BF16, f"CUDA {torch.cuda.get_device_name()} with bf16")
        return PrecisionChoice(AUTO, FP32, f"CUDA {torch.cuda.get_device_name()}, no bf16")
    if accelerator not in ("auto", "cpu"):
        return PrecisionChoice(AUTO, FP32, f"accelerator {accelerator}")
    capability = torch.backends.cpu.get_cpu_capability()
    flags = cpu_bf16_flags()
    if flags:
        return PrecisionChoice(AUTO, BF16, f"CPU capability {capability}, native bf16: {flags}")
    return PrecisionChoice(AUTO, FP32, f"CPU capability {capability}, no native bf16")
