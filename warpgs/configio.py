"""Reading config values: YAML files with ``base:`` chains, ``key=value`` overrides, and typed assignment
into dataclasses with errors that name the key and where it came from. A leaf module: the option classes
of every part (training, pseudo views, densification) are read through it, and ``warpgs.config`` builds
the run's tree on top of it."""

from __future__ import annotations

import dataclasses
import types
import typing
from pathlib import Path
from typing import Any

import yaml

REPO_ROOT = Path(__file__).resolve().parents[1]
# the one config folder: the checkout's configs/, or the copy an installed wheel carries (warpgs/configs)
CONFIG_DIR = REPO_ROOT / "configs" if (REPO_ROOT / "configs").is_dir() else Path(__file__).resolve().parent / "configs"


class ConfigError(ValueError):
    pass


def _type_ok(value, tp) -> tuple[bool, Any]:
    """(accepted, coerced value) of ``value`` for the annotation ``tp``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            ok, v = _type_ok(value, arg)
            if ok:
                return True, v
        return False, value
    if tp is type(None):
        return value is None, value
    if tp is Any:
        return True, value
    base = origin or tp
    if base is bool:
        return isinstance(value, bool), value
    if base is int:
        return isinstance(value, int) and not isinstance(value, bool), value
    if base is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return True, float(value)
        if isinstance(value, str):  # YAML 1.1 reads '1e-3' (no dot) as a string
            try:
                return True, float(value)
            except ValueError:
                return False, value
        return False, value
    if base is str:
        return isinstance(value, str), value
    if base is list:
        if isinstance(value, (list, tuple)):
            return True, list(value)
        return False, value
    if base is dict:
        return isinstance(value, dict), value
    return isinstance(value, base), value


def apply_values(obj, values: dict, where: str) -> None:
    """Sets the fields of the dataclass ``obj`` (recursing into nested dataclasses) from ``values``,
    coerced to their annotated types; unknown keys and wrong types raise ``ConfigError`` naming
    ``where``. The one reader of every config section (training, pseudo views, densification)."""
    if not isinstance(values, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(values).__name__}")
    hints = typing.get_type_hints(type(obj))
    names = [f.name for f in dataclasses.fields(obj)]
    for key, value in values.items():
        if key not in names:
            raise ConfigError(f"{where}: unknown key {key!r}; valid keys: {', '.join(names)}")
        cur = getattr(obj, key)
        if dataclasses.is_dataclass(cur):
            if not isinstance(value, dict):
                raise ConfigError(f"{where}.{key}: expected a mapping of {type(cur).__name__} fields, got {value!r}")
            apply_values(cur, value, f"{where}.{key}")
            continue
        ok, v = _type_ok(value, hints[key])
        if not ok:
            raise ConfigError(f"{where}.{key}: {value!r} is not a valid {hints[key]}")
        setattr(obj, key, v)


def read_yaml(path: str | Path, _seen=None) -> dict:
    """A config file as a dict, with its ``base:`` file (relative to it) merged underneath."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    seen = set() if _seen is None else _seen
    if path.resolve() in seen:
        raise ConfigError(f"{path}: 'base' chain loops")
    seen.add(path.resolve())
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: cannot parse YAML ({e})") from e
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    base = data.pop("base", None)
    if base:
        data = merge(read_yaml(path.parent / base, seen), data)
    return data


def merge(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def parse_override(text: str) -> dict:
    """``"train.iterations=500"`` -> ``{"train": {"iterations": 500}}`` (value parsed as YAML)."""
    if "=" not in text:
        raise ConfigError(f"--set {text!r}: expected key=value, e.g. train.iterations=500")
    key, raw = text.split("=", 1)
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError as e:
        raise ConfigError(f"--set {text!r}: cannot parse the value ({e})") from e
    out: dict = value
    for part in reversed(key.strip().split(".")):
        if not part:
            raise ConfigError(f"--set {text!r}: empty key component")
        out = {part: out}
    return out


__all__ = ["CONFIG_DIR", "REPO_ROOT", "ConfigError", "apply_values", "merge", "parse_override", "read_yaml"]
