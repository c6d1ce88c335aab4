"""Run folders are shared: what their ``config.yaml`` may build is a fixed list.

A run's config names the classes that rebuild its networks (``_target_``). Hydra's
``instantiate`` calls whatever a ``_target_`` names, so a config copied from someone else's run
folder could call any function (``torch.load(..., weights_only=False)``, ``os.system``). Every
loader of a run therefore goes through :func:`instantiate_from_run`, which resolves the config,
checks every ``_target_`` in it against :data:`LOADABLE_TARGETS` and refuses the file, naming it
and the offending entry, before anything is called.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.utils import instantiate
from omegaconf import DictConfig, ListConfig, OmegaConf

# Everything a train_* run legitimately rebuilds from its config: networks, their parts, the
# frozen text tower and the (partial) optimizers that ARFlow's module config carries.
# tests/utils/test_run_config.py checks that every class our model/text configs name is here.
LOADABLE_TARGETS: frozenset[str] = frozenset(
    {
        "intermask.vq.model.MotionVQVAE",
        "intermask.vq.views.InterHumanView",
        "intermask.vq.views.InterXView",
        "intermask.vq.views.HumanML3DView",
        "intermask.vq.convolutions.MotionEncoder",
        "intermask.vq.convolutions.MotionDecoder",
        "intermask.vq.quantizers.ResidualQuantizer",
        "intermask.interm.model.InterMTransformer",
        "intermask.momask.model.MaskedTransformer",
        "intermask.momask.model.ResidualTransformer",
        "intermask.text.cache.TextFeatureCache",
        "intermask.text.clip_encoder.FrozenCLIPTextEncoder",
        "intermask.evaluator.interclip.InterCLIP",
        "intermask.evaluator.gru_matcher.GRUMatcher",
        "intermask.evaluator.humanml3d_matcher.HumanML3DMatcher",
        "intermask.reaction.module.ARFlowModule",
        "intermask.reaction.network.ReactionDecoder",
        "intermask.physics.capsules.BodyProxy",
        "torch.optim.AdamW",
        "torch.optim.Adam",
    }
)


class UnsafeRunConfig(ValueError):
    """A run config names something outside :data:`LOADABLE_TARGETS`."""


def _walk(node: Any, where: str):
    """Yield (path, key, value) for every leaf of a plain container tree."""
    if isinstance(node, dict):
        for key, value in node.items():
            path = f"{where}.{key}" if where else str(key)
            if not isinstance(value, dict | list):
                yield path, key, value
            else:
                yield from _walk(value, path)
    elif isinstance(node, list):
        for index, value in enumerate(node):
            path = f"{where}[{index}]"
            if isinstance(value, dict | list):
                yield from _walk(value, path)
            else:
                yield path, index, value


def check_targets(
    node: DictConfig | ListConfig | dict | list, *, source: str | Path, section: str = ""
) -> Any:
    """Resolve ``node`` (the config's ``section``, for the messages) and refuse it if any
    ``_target_`` is not loadable; -> the resolved plain container (what is then instantiated,
    so nothing changes between check and use)."""
    if isinstance(node, DictConfig | ListConfig):
        try:
            node = OmegaConf.to_container(node, resolve=True)
        except Exception as error:  # an interpolation or resolver the file should not hold
            raise UnsafeRunConfig(f"{source}: cannot resolve the run config ({error})") from error
    for where, key, value in _walk(node, section):
        if isinstance(value, str) and "${" in value:
            # an escaped interpolation survives resolution and instantiate would resolve it
            # (``oc.create`` could build a new ``_target_`` after this check)
            raise UnsafeRunConfig(
                f"{source}: refusing the value {value!r} at {where}: a run config holds "
                "resolved values, not interpolations"
            )
        if key != "_target_":
            continue
        target = value
        if not isinstance(target, str) or target not in LOADABLE_TARGETS:
            raise UnsafeRunConfig(
                f"{source}: refusing to build {target!r} (at {where}): a run config may only "
                "name the framework's network, text-tower and optimizer classes "
                "(intermask.utils.run_config.LOADABLE_TARGETS). Was the file edited or copied "
                "from an untrusted run folder?"
            )
    return node


def instantiate_from_run(
    node: DictConfig | dict, *, source: str | Path, section: str = "", **overrides: Any
) -> Any:
    """:func:`check_targets`, then ``hydra.utils.instantiate`` on the checked container."""
    return instantiate(check_targets(node, source=source, section=section), **overrides)
