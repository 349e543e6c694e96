"""The command line checked before Hydra runs it: Hydra's composition errors as one line.

Hydra reports a mistyped key (``robot.forarm=0.4``) in five lines, suggests ``+robot.forarm=0.4`` (which would
add a key no job reads) and exits 1. :func:`check_overrides` composes the command line's config first (Hydra's
compose API, ~0.3 s) and :func:`composition_error_line` turns a failure into one line: the key, what is wrong
and the valid keys of its block (:func:`deltajax.config.valid_keys`, else the keys of the composed block), or
the choices of a config group. :mod:`deltajax.run` prints it with exit status 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Optional
import itertools

from omegaconf import DictConfig, OmegaConf

from .config import valid_keys

__all__ = ["check_overrides", "composition_error_line", "compose_config", "sweep_jobs"]

#: Hydra flags after which the next argument is the flag's value, not an override.
_FLAGS_WITH_VALUE = {"--cfg", "-c", "--package", "-p", "--info", "-i"}
#: Hydra flags that change where the config comes from or what runs: Hydra alone handles those command lines.
_FLAGS_HYDRA_ONLY = {"--config-path", "-cp", "--config-name", "-cn", "--config-dir", "-cd", "--experimental-rerun",
                     "--shell-completion", "-sc", "--version", "--hydra-help", "--info", "-i"}


def compose_config(overrides: list, config_dir: str):
    """The composed config (Hydra's compose API) for ``overrides`` with ``config_dir`` as the primary config dir."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=config_dir, version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def _keys_at(parent: str, overrides: list, config_dir: str) -> Optional[list]:
    """The keys of the composed config's block ``parent`` ("" for the top level), or None if it cannot be
    composed (for a block no schema describes)."""
    try:
        node = compose_config(overrides, config_dir)
        node = OmegaConf.select(node, parent) if parent else node
    except Exception:  # noqa: BLE001 - only an error message's detail: the caller reports the original error
        return None
    return sorted(str(k) for k in node.keys()) if isinstance(node, DictConfig) else None


def composition_error_line(exc: Exception, overrides: Iterable[str], config_dir: str) -> str:
    """One line for an error of Hydra's composition of ``overrides`` (an unknown key, a value of the wrong
    type, a missing preset, an unparsable override): the key, the value and what is allowed. Hydra's own
    message suggests ``+key=value`` for a mistyped key, which would only add a key no job reads; this line
    lists the valid keys of that block instead (:func:`deltajax.config.valid_keys`, else the composed block)."""
    import difflib

    from hydra.errors import MissingConfigException
    from omegaconf.errors import ConfigKeyError, OmegaConfBaseException

    overrides = list(overrides)
    cause = exc.__cause__
    full_key = getattr(cause, "full_key", None) if isinstance(cause, OmegaConfBaseException) else None
    first = str(cause or exc).strip().splitlines()[0] if str(cause or exc).strip() else type(exc).__name__
    if isinstance(exc, MissingConfigException) and getattr(exc, "missing_cfg_file", None):
        group, _, name = str(exc.missing_cfg_file).rpartition("/")
        options = ", ".join(exc.options or [])
        return f"{group}={name} is not a choice of {group}; choose one of: {options}"
    if full_key and isinstance(cause, (ConfigKeyError, AttributeError)) and "Could not override" in str(exc):
        parent, _, leaf = str(full_key).rpartition(".")
        experiment = None
        for o in overrides:
            if o.startswith("experiment="):
                experiment = o.split("=", 1)[1]
        exp_name = experiment or _default_experiment(config_dir)
        keys = valid_keys(str(full_key), exp_name)
        if keys is None:
            rest = [o for o in overrides if o.split("=", 1)[0].lstrip("+~") != full_key]
            keys = _keys_at(parent, rest, config_dir)
        where = f"of {parent}" if parent else "at the top level"
        if parent == "experiment" and exp_name:
            where = f"of experiment {exp_name}"
        elif parent.startswith("experiment.") and exp_name:
            where += f" (experiment {exp_name})"
        line = f"{full_key} is not a setting {where}"
        if keys:
            close = difflib.get_close_matches(leaf, keys, n=1)
            line += (f" (did you mean {parent + '.' if parent else ''}{close[0]}?)" if close else "")
            line += f"; valid keys: {', '.join(keys)}"
        return line
    if full_key:
        return f"{full_key}: {first}"
    if "Ambiguous value for argument" in str(exc):
        arg = str(exc).split("'")[1]
        key, _, value = arg.partition("=")
        return (f"{arg} lists several values: add -m to sweep over them (a multirun), or write "
                f"{key}=[{value}] for a list")
    return "; ".join(ln.strip() for ln in str(exc).strip().splitlines()
                     if ln.strip() and not ln.startswith(("Config search path", "\tprovider=")))


def _default_experiment(config_dir: str) -> Optional[str]:
    """The experiment a command line without ``experiment=`` runs (configs/config.yaml's defaults list)."""
    for entry in OmegaConf.load(Path(config_dir) / "config.yaml").get("defaults", []):
        if isinstance(entry, DictConfig) and "experiment" in entry:
            return str(entry.experiment)
    return None


def _split(args: Iterable[str]) -> Optional[tuple]:
    """(the config overrides of a command line, without Hydra's own settings; whether it is a multirun), or None
    for a command line with flags that change the config source (Hydra alone handles those)."""
    overrides, skip, multirun = [], False, False
    for a in args:
        if skip:
            skip = False
        elif a in _FLAGS_HYDRA_ONLY or a.split("=", 1)[0] in _FLAGS_HYDRA_ONLY:
            return None
        elif a in ("-m", "--multirun"):
            multirun = True
        elif a in _FLAGS_WITH_VALUE:
            skip = True
        elif not a.startswith("-"):
            overrides.append(a)
    return [o for o in overrides if not o.lstrip("+~").startswith("hydra")], multirun  # Hydra's own settings


def sweep_jobs(args: Iterable[str]) -> Optional[list]:
    """The overrides of every job of a multirun command line (``-m``), in the basic sweeper's order (the product
    of every sweep's values); None when it is not a multirun, or holds a sweep only Hydra's sweeper can expand
    (a range, an interval, a glob)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    split = _split(args)
    if split is None or not split[1]:
        return None
    values = []
    for o in OverridesParser.create().parse_overrides(split[0]):
        if not o.is_sweep_override():
            values.append([o.input_line])
        elif o.is_discrete_sweep() and o.value_type.name != "GLOB_CHOICE_SWEEP":
            values.append([f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()])
        else:
            return None
    return [list(c) for c in itertools.product(*values)]


def check_overrides(args: Iterable[str], config_dir: str) -> Optional[str]:
    """Compose the config of a command line the way Hydra will, before Hydra runs it; returns the one-line
    error (:func:`composition_error_line`) or None if it composes. A multirun (``-m``) is checked once per
    combination of its config-group choices (``experiment=a,b``), each value sweep at its first value.
    Command lines with flags that change the config source are left to Hydra."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    split = _split(args)
    if split is None:
        return None
    overrides, multirun = split
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except HydraException as e:
        return f"cannot read the command line: {composition_error_line(e, overrides, config_dir)}"
    combos = [[]]
    if multirun:
        fixed, choices = [], []
        for o in parsed:
            key = o.get_key_element()
            if o.is_sweep_override():
                if not o.is_discrete_sweep() or o.value_type.name == "GLOB_CHOICE_SWEEP":
                    return None  # a sweep Hydra's sweeper alone can expand
                values = [f"{key}={v}" for v in o.sweep_string_iterator()]
                is_group = "/" in o.key_or_group or (Path(config_dir) / o.key_or_group).is_dir()
                if is_group:
                    choices.append(list(dict.fromkeys(values)))
                else:
                    fixed.append(values[0])
            else:
                fixed.append(o.input_line)
        combos = [fixed + list(c) for c in itertools.product(*choices)]
    else:
        combos = [overrides]
    for ov in combos:
        try:
            compose_config(ov, config_dir)
        except HydraException as e:
            return composition_error_line(e, ov, config_dir)
    return None
