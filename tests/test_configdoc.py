"""docs/configuration.md is what ``python -m warpgs.configdoc`` prints: every key of the configuration with its
default and the comment beside its field."""

import dataclasses
from pathlib import Path

from warpgs.config import Config, GuardConfig, TrainConfig
from warpgs.configdoc import field_comments, render

DOC = Path(__file__).resolve().parents[1] / "docs" / "configuration.md"


def test_the_committed_file_is_current():
    assert DOC.read_text() == render(), "run: python -m warpgs.configdoc > docs/configuration.md"


def test_every_key_is_listed_with_its_default_and_its_comment():
    text = render()
    for f in dataclasses.fields(TrainConfig):
        assert f"| `train.{f.name}` |" in text
    # a field's comment and the comment lines that continue it, joined
    notes = field_comments(GuardConfig)
    assert notes["sync_every"].startswith("steps between host reads") and notes["sync_every"].endswith(
        "None: 10 on CUDA, 1 (every step) on the CPU")
    assert f"| `train.iterations` | `{Config().train.iterations!r}` |" in text
    assert "## pseudo.trajectory" in text  # nested sections of other packages' dataclasses
    assert "| `guard.sync_every` |" in text and "| `train.sync_every` |" not in text  # a key where it lives now
