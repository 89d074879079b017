"""``python -m simlan_data.run --help``, composed once.

Hydra's own ``--help`` lists every config group by building a fresh config repository for each
group (a deep copy of the ConfigStore, where our typed schema and every algorithm's node live):
about 120 copies, 2 s of the 2.2 s the command took. Here the groups come from the config
directory and the ConfigStore directly, and the config is composed once, as the run composes it;
the text is Hydra's template (``conf/hydra/help/simlan.yaml``) with the same substitutions.
A command line that adds config directories (``--config-dir``, ``hydra.searchpath``) or asks for
Hydra's options (``--hydra-help``) gets Hydra's own help. The text is kept in a cache that the
``-m`` shim and ``simlan-run`` print before importing the app (:mod:`simlan_data.apps.help_cache`).
"""

from __future__ import annotations

import string
import sys
from collections.abc import Sequence
from pathlib import Path

from omegaconf import OmegaConf

from simlan_data.apps.help_cache import help_overrides, store_help, wants_fast_help
from simlan_data.constants import CONF_DIR

__all__ = ["config_groups", "help_text", "print_help", "wants_fast_help"]


def config_groups(conf_dir: Path = CONF_DIR) -> dict[str, list[str]]:
    """Every group a run may choose from (not Hydra's own), with its options."""
    from hydra.core.config_store import ConfigStore

    groups: dict[str, set[str]] = {}
    for path in sorted(conf_dir.rglob("*.yaml")):
        group = path.parent.relative_to(conf_dir).as_posix()
        if group != "." and group.split("/")[0] != "hydra":
            groups.setdefault(group, set()).add(path.stem)
    store = ConfigStore.instance()

    def walk(prefix: str) -> None:
        for name in store.list(prefix) if prefix else store.list(""):
            path = f"{prefix}/{name}" if prefix else name
            if name.endswith(".yaml"):
                if prefix and prefix.split("/")[0] != "hydra":
                    groups.setdefault(prefix, set()).add(name[: -len(".yaml")])
            elif name != "hydra":
                walk(path)

    walk("")
    return {g: sorted(options) for g, options in sorted(groups.items())}


def help_text(overrides: Sequence[str]) -> str:
    """The help, for the config ``overrides`` compose to (as ``--help KEY=VALUE`` shows)."""
    from hydra import compose, initialize_config_dir

    from simlan_data.config.schema import register_configs

    register_configs(list(overrides))
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
    help_cfg = cfg.hydra.help
    job = OmegaConf.masked_copy(cfg, [str(k) for k in cfg if k != "hydra"])
    groups = "".join(f"{g}: {', '.join(options)}\n" for g, options in config_groups().items())
    return string.Template(str(help_cfg.template)).safe_substitute(
        APP_CONFIG_GROUPS=groups, CONFIG=OmegaConf.to_yaml(job), FLAGS_HELP="", HYDRA_CONFIG_GROUPS=""
    )


def print_help(argv: Sequence[str]) -> None:
    """Compose the help, print it, and keep it for the next ``--help`` (help_cache)."""
    text = help_text(help_overrides(argv)) + "\n"
    sys.stdout.write(text)
    store_help(argv, text)
