"""What a registry of one-module parts shares (the regularisers, ``warpgs.regularizers``; the background
components, ``warpgs.backgrounds``): each module names its settings' dataclass ``CONFIG`` (with the keys of
``train`` it took in ``LEGACY``) and a ``build(cfg, ctx)`` that returns its part or None (off for this run)."""

from __future__ import annotations

import dataclasses


def registry_section(cls_name: str, modules: dict, module_name: str, doc: str) -> tuple[type, dict]:
    """(the config section of a registry: one subsection per module, its ``CONFIG``; the keys of ``train``
    before the section existed -> (module's name, its key): ``warpgs.config``'s ``MOVED``)."""
    section = dataclasses.make_dataclass(
        cls_name, [(name, mod.CONFIG, dataclasses.field(default_factory=mod.CONFIG)) for name, mod in modules.items()])
    section.__doc__ = doc
    section.__module__ = module_name
    legacy = {old: (name, new) for name, mod in modules.items()
              for old, new in getattr(mod.CONFIG, "LEGACY", {}).items()}
    return section, legacy


def build_registered(modules: dict, cfg, ctx, names=None) -> dict:
    """{name: part} of the modules (``names``, default all, in the registry's order) whose ``build`` returns one."""
    items = {}
    for name in names or modules:
        part = modules[name].build(cfg, ctx)
        if part is not None:
            items[name] = part
    return items
