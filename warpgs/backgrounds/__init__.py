"""What the renders see behind the Gaussians besides a colour: one module per component, built through
``REGISTRY`` and asked in its order (the first that draws a camera's background wins).

    comps = Backgrounds.build(cfg, ctx)     # the ones on for this run (ctx: warpgs.engine.context.Context)
    image = comps.image(cam, keep)          # [H, W, 3], or None: the colour (warpgs.engine.background)
    comps.save(out)                         # their files in the run folder (far_field.json)

To add one (the far field is the example, ``warpgs/backgrounds/far_field.py``): a module with its settings'
dataclass (``CONFIG``, the section ``backgrounds.<name>``), a ``BackgroundComponent`` subclass and a
``build(cfg, ctx)`` that returns it or None (off), a line below, and a test (tests/test_farfield.py).
"""

from __future__ import annotations

import importlib

from warpgs.backgrounds.base import BackgroundComponent
from warpgs.registry import build_registered, registry_section

# name -> module (warpgs.backgrounds.<module>), in the order they are asked
REGISTRY = {
    "far_field": "far_field",
}

MODULES = {name: importlib.import_module(f"warpgs.backgrounds.{m}") for name, m in REGISTRY.items()}

# the config's section ``backgrounds`` (one subsection per component) and the keys of ``train`` before it existed
BackgroundsConfig, LEGACY_TRAIN_KEYS = registry_section(
    "BackgroundsConfig", MODULES, __name__,
    "What the renders see behind the Gaussians besides train.background (``backgrounds.<name>``; "
    "warpgs/backgrounds/<name>.py).")


class Backgrounds:
    """The components on for one trainer, by name in the registry's order."""

    def __init__(self, items: dict[str, BackgroundComponent]):
        self.items = items

    @classmethod
    def build(cls, cfg, ctx) -> "Backgrounds":
        return cls(build_registered(MODULES, cfg, ctx))

    def get(self, name: str) -> BackgroundComponent | None:
        return self.items.get(name)

    def image(self, cam, keep: bool = True):
        for comp in self.items.values():
            img = comp.image(cam, keep)
            if img is not None:
                return img
        return None

    def times(self) -> dict[str, float]:
        """Seconds each component's fit took, as metrics.json's stage_times_s keys (``far_field_s``)."""
        return {f"{name}_s": comp.time for name, comp in self.items.items() if comp.time is not None}

    def save(self, out) -> None:
        for comp in self.items.values():
            comp.save(out)


__all__ = ["BackgroundComponent", "Backgrounds", "BackgroundsConfig", "LEGACY_TRAIN_KEYS", "MODULES", "REGISTRY"]
