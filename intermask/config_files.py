"""Where the Hydra configs are: the checkout's top-level ``configs/`` (a clone, an editable
install), else the copy a wheel ships inside the package (``intermask/_configs``, see
``pyproject.toml``). Every job and ``intermask generate`` find them through :func:`config_dir`,
so an installed package runs from any folder.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
CHECKOUT_CONFIGS = PACKAGE_DIR.parent / "configs"
PACKAGED_CONFIGS = PACKAGE_DIR / "_configs"


def config_dir() -> Path:
    """The configs folder of this installation (named in the error when neither exists)."""
    for candidate in (CHECKOUT_CONFIGS, PACKAGED_CONFIGS):
        if (candidate / "train_vq.yaml").is_file():
            return candidate
    raise FileNotFoundError(
        f"no Hydra configs at {CHECKOUT_CONFIGS} (a checkout) or {PACKAGED_CONFIGS} (a wheel): "
        "reinstall the package"
    )
