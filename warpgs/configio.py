"""Reading config values: YAML files with ``base:`` chains, ``key=value`` overrides, and typed assignment
into dataclasses with errors that name the key and where it came from. A leaf module: the option classes
of every part (training, pseudo views, densification) are read through it, and ``warpgs.config`` builds
the run's tree on top of it."""

from __future__ import annotations

import dataclasses
import functools
import math
import re
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
        if isinstance(value, bool):  # YAML 1.1 reads on / off (and yes / no) as booleans: an option's words
            return True, "on" if value else "off"
        return isinstance(value, str), value
    if base is list:
        if isinstance(value, (list, tuple)):
            return True, list(value)
        return False, value
    if base is dict:
        return isinstance(value, dict), value
    return isinstance(value, base), value


def type_name(tp) -> str:
    """``int``, ``float | None``, ``int | str | None``: an annotation as a user reads it."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return " | ".join(type_name(a) for a in typing.get_args(tp))
    if tp is type(None):
        return "None"
    return getattr(typing.get_origin(tp) or tp, "__name__", str(tp))


# ----------------------------------------------------------------------------------------------
# ranges: each option class lists the ranges of its fields in a class attribute ``LIMITS`` (a dict of
# field name -> rule, next to the fields), and ``apply_values`` checks every value it sets against it.
# A rule is one or more alternatives joined by " or ": a bound ("> 0", ">= 1", "< 1", "<= 100"), an
# interval ("[0, 1]", "[0, 1)", "(0, 1]", "(0, 1)") or a set of words ("{weight, weight_volume}").
# None passes (where the type allows it) and so do booleans; numbers must be finite and keep one of the
# rule's bounds, strings must be one of its words (a rule without words leaves strings to the type check);
# a list's items are checked one by one.

_BOUND = re.compile(r"^(>=|>|<=|<)\s*(\S+)$")
_INTERVAL = re.compile(r"^([\[(])\s*([^,\s]+)\s*,\s*([^\])\s]+)\s*([\])])$")


@functools.lru_cache(maxsize=None)
def _rule(rule: str) -> tuple[list, frozenset | None]:
    """A rule's numeric tests (value -> bool) and its words (None: it has none)."""
    tests, words = [], None
    for alt in (a.strip() for a in rule.split(" or ")):
        m, n = _BOUND.match(alt), _INTERVAL.match(alt)
        if alt.startswith("{") and alt.endswith("}"):
            words = (words or frozenset()) | frozenset(w.strip() for w in alt[1:-1].split(",") if w.strip())
        elif m:
            op, b = m.group(1), float(m.group(2))
            tests.append({">": lambda v, b=b: v > b, ">=": lambda v, b=b: v >= b,
                          "<": lambda v, b=b: v < b, "<=": lambda v, b=b: v <= b}[op])
        elif n:
            lo, hi, closed_lo, closed_hi = float(n.group(2)), float(n.group(3)), n.group(1) == "[", n.group(4) == "]"
            tests.append(lambda v, lo=lo, hi=hi, cl=closed_lo, ch=closed_hi:
                         (v >= lo if cl else v > lo) and (v <= hi if ch else v < hi))
        else:
            raise ValueError(f"range rule {rule!r}: {alt!r} is not '> x', '>= x', '< x', '<= x', an interval like "
                             "'[0, 1)' or a set of words like '{a, b}'")
    return tests, words


def _describe(rule: str) -> str:
    parts = []
    for alt in (a.strip() for a in rule.split(" or ")):
        if alt.startswith("{"):
            parts.append("one of " + ", ".join(w.strip() for w in alt[1:-1].split(",")))
        else:
            parts.append(alt if alt[0] in "<>" else f"in {alt}")
    return "must be " + " or ".join(parts)


def limit_error(value, rule: str) -> str | None:
    """Why ``value`` breaks ``rule`` (a ``LIMITS`` rule), or None when it keeps it."""
    tests, words = _rule(rule)
    for v in value if isinstance(value, (list, tuple)) else [value]:
        if v is None or isinstance(v, bool):
            continue
        if isinstance(v, str):
            if words is not None and v not in words:
                return _describe(rule)
        elif isinstance(v, (int, float)):
            if not math.isfinite(v):
                return "must be a finite number"
            if not any(t(v) for t in tests):
                return _describe(rule)
    return None


def limits_of(cls) -> dict:
    """The ``LIMITS`` of an option class (its own; those of a base class underneath)."""
    out: dict = {}
    for klass in reversed(cls.__mro__):
        out.update(klass.__dict__.get("LIMITS", {}))
    return out


def check_limits(obj, where: str = "config", prefix: str = "") -> None:
    """Checks every field of the dataclass ``obj`` (recursing into nested ones) against its class's
    ``LIMITS``; ``ConfigError`` names the first key out of range. For options built in code, which
    ``apply_values`` never saw."""
    lim = limits_of(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            check_limits(value, where, f"{prefix}{f.name}.")
        elif f.name in lim:
            why = limit_error(value, lim[f.name])
            if why:
                raise ConfigError(f"{prefix}{f.name} = {value!r} (from {where}): {why}")


def apply_values(obj, values: dict, where: str, prefix: str = "") -> None:
    """Sets the fields of the dataclass ``obj`` (recursing into nested dataclasses) from ``values``,
    coerced to their annotated types and checked against the class's ``LIMITS``; unknown keys, wrong
    types and values out of range raise ``ConfigError`` naming the key and ``where`` the values came from
    (a file, ``--set key=value``, a flag). The one reader of every config section (training, pseudo
    views, densification). ``prefix``: the dotted path of ``obj`` in the whole config."""
    if not isinstance(values, dict):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'} (from {where}): expected a mapping, got "
                          f"{type(values).__name__}")
    hints = typing.get_type_hints(type(obj))
    names = [f.name for f in dataclasses.fields(obj)]
    lim = limits_of(type(obj))
    for key, value in values.items():
        if key not in names:
            raise ConfigError(f"{prefix.rstrip('.') or 'config'} (from {where}): unknown key {key!r}; "
                              f"valid keys: {', '.join(names)}")
        cur = getattr(obj, key)
        if dataclasses.is_dataclass(cur):
            if not isinstance(value, dict):
                raise ConfigError(f"{prefix}{key} (from {where}): expected a mapping of {type(cur).__name__} "
                                  f"fields, got {value!r}")
            apply_values(cur, value, where, f"{prefix}{key}.")
            continue
        ok, v = _type_ok(value, hints[key])
        if not ok:
            raise ConfigError(f"{prefix}{key} = {value!r} (from {where}): not a valid {type_name(hints[key])}")
        if any(isinstance(x, float) and not math.isfinite(x) for x in (v if isinstance(v, list) else [v])):
            raise ConfigError(f"{prefix}{key} = {value!r} (from {where}): must be a finite number")
        why = limit_error(v, lim[key]) if key in lim else None
        if why:
            raise ConfigError(f"{prefix}{key} = {v!r} (from {where}): {why}")
        setattr(obj, key, v)


class DuplicateKeyError(yaml.YAMLError):
    """A mapping of a YAML file sets one key twice; the message names the key and both lines."""


class UniqueKeyLoader(yaml.SafeLoader):
    """yaml's SafeLoader, except that a mapping that sets one key twice is a ``DuplicateKeyError`` (SafeLoader
    keeps the last value without a word)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            lines: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = lines.setdefault(key, key_node.start_mark.line + 1)
                except TypeError:  # an unhashable key: SafeLoader's own error
                    continue
                if first != key_node.start_mark.line + 1:
                    raise DuplicateKeyError(f"line {key_node.start_mark.line + 1}: key {key!r} is set twice "
                                            f"(first at line {first})")
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: str | Path, _seen=None) -> dict:
    """A config file as a dict, with its ``base:`` file (relative to it; or a list of files, merged in order)
    merged underneath. A key set twice in one mapping is an error (``UniqueKeyLoader``)."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder, not a config file")
    if path.exists() and not path.is_file():
        raise ConfigError(f"{path}: is not a regular file (a config is a YAML file)")
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    seen = set() if _seen is None else _seen
    if path.resolve() in seen:
        raise ConfigError(f"{path}: 'base' chain loops")
    seen.add(path.resolve())
    try:
        data = yaml.load(path.read_text(encoding="utf-8"), Loader=UniqueKeyLoader) or {}
    except DuplicateKeyError as e:
        raise ConfigError(f"{path}: {e}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: cannot parse YAML ({' '.join(str(e).split())})") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text at byte {e.start}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    base = data.pop("base", None)
    if base:
        bases = base if isinstance(base, list) else [base]
        if not all(isinstance(b, str) for b in bases):
            raise ConfigError(f"{path}: base = {base!r}: expected the name of another config file, or a list of them")
        under: dict = {}
        for b in bases:
            try:
                under = merge(under, read_yaml(path.parent / b, set(seen)))
            except ConfigError as e:
                raise ConfigError(f"{path}: base: {e}") from None
        data = merge(under, data)
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


__all__ = ["CONFIG_DIR", "REPO_ROOT", "ConfigError", "DuplicateKeyError", "UniqueKeyLoader", "apply_values", "check_limits", "limit_error", "limits_of", "merge",
           "parse_override", "read_yaml", "type_name"]
