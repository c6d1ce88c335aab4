"""Where the Hydra configs are: the checkout's top-level ``configs/`` (a clone, an editable
install), else the copy a wheel ships inside the package (``intermask/_configs``, see
``pyproject.toml``). Every job and ``intermask generate`` find them through :func:`config_dir`,
so an installed package runs from any folder.

Importing this module registers the resolvers the configs use (``${div:a,b}``): whoever finds
the configs here can compose and resolve them, whichever entry point imported it first (a fresh
``intermask convert-reference`` imports no training module).
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

PACKAGE_DIR = Path(__file__).resolve().parent
CHECKOUT_CONFIGS = PACKAGE_DIR.parent / "configs"
PACKAGED_CONFIGS = PACKAGE_DIR / "_configs"

# ${div:a,b} in configs, e.g. the generator's warm-up of a quarter epoch as a share of all steps
RESOLVERS = {"div": lambda numerator, denominator: numerator / denominator}
for _name, _resolver in RESOLVERS.items():
    if not OmegaConf.has_resolver(_name):
        OmegaConf.register_new_resolver(_name, _resolver)


def config_dir() -> Path:
    """The configs folder of this installation (named in the error when neither exists)."""
    for candidate in (CHECKOUT_CONFIGS, PACKAGED_CONFIGS):
        if (candidate / "train_vq.yaml").is_file():
            return candidate
    raise FileNotFoundError(
        f"no Hydra configs at {CHECKOUT_CONFIGS} (a checkout) or {PACKAGED_CONFIGS} (a wheel): "
        "reinstall the package"
    )
