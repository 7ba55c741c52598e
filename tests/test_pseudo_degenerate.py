"""Pseudo views a video model can produce must not break the full method (issue 60): black, constant, noise,
NaN frames, or a copy of the input. A test backend (the weight-free one or the tiny random SVD, wrapped) returns
each kind; the full method runs its cycle on the embedded synthetic scene (CPU, few iterations) through
pseudo-view generation, densification from them and training on them: no exception, a finite model, and NaN
frames dropped with one warning line."""

from __future__ import annotations

import pytest
import torch

from warpgs.pseudo.backends import GaussianVideoBackend
from warpgs.pseudo.sampler import condition_passes

KINDS = ("black", "constant", "noise", "nan", "copy")


class DegenerateBackend:
    """Wraps a backend (the weight-free one, or the tiny random SVD) and replaces its decoded frames by one
    degenerate kind; everything else is the wrapped backend's."""

    def __init__(self, inner, kind: str):
        self.inner, self.kind = inner, kind
        self.start = None
        self.gen = torch.Generator().manual_seed(0)

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def condition_batch(self, images, n_frames, priors=None, generator=None):
        self.start = images[0].clone()  # the forward pass's start input
        return condition_passes(self.inner, images, n_frames, priors, generator)

    def decode(self, latents, size):
        frames = self.inner.decode(latents, size)
        if self.kind == "black":
            return torch.zeros_like(frames)
        if self.kind == "constant":
            return torch.full_like(frames, 0.37)
        if self.kind == "noise":
            return torch.rand(frames.shape, generator=self.gen).to(frames)
        if self.kind == "nan":
            frames = frames.clone()
            frames[1, 3:7, 2:5] = float("nan")  # one interior frame has a few NaN pixels, another is all NaN
            frames[-2] = float("nan")
            return frames
        return self.start.to(frames).expand_as(frames).contiguous()  # every frame the start input


@pytest.fixture(scope="module")
def tiny_svd(tmp_path_factory):
    pytest.importorskip("diffusers")
    pytest.importorskip("transformers")
    from test_svd_tiny import build_tiny_svd

    return build_tiny_svd(tmp_path_factory.mktemp("svd") / "tiny")


def make_inner(name: str, request):
    if name == "default":
        return GaussianVideoBackend()
    from warpgs.pseudo.backends import SVDBackend, SVDConfig

    return SVDBackend.from_pretrained(request.getfixturevalue("tiny_svd"), cfg=SVDConfig(width=32, height=32))


@pytest.mark.parametrize("inner", ["default", "svd"])
@pytest.mark.parametrize("kind", KINDS)
def test_full_method_survives_degenerate_pseudo_views(kind, inner, request, monkeypatch, capfd):
    import warpgs.console as console
    import warpgs.pseudo.views as views
    from warpgs.config import build_config
    from warpgs.data import load_scene
    from warpgs.pipelines.full import FullMethod
    from warpgs.train import Trainer

    backend = DegenerateBackend(make_inner(inner, request), kind)
    monkeypatch.setattr(views, "backend_from_config", lambda cfg, device="cpu": backend)
    monkeypatch.setattr(console, "_said", set())  # warn_once's memory: this run's lines are said afresh
    n_frames = 5
    cfg = build_config([{"method": "full", "train": {"device": "cpu", "progress": False, "iterations": 16},
                         "model": {"init": "box", "init_num": 300, "init_box": [-1, -1, 2, 1, 1, 4]},
                         "full": {"pseudo_loss": "l1", "cycles": 1, "baseline_fraction": 0.5},
                         "pseudo": {"trajectory": {"n_frames": n_frames}, "sampler": {"steps": 2}}}])
    scene = load_scene("synthetic", views=3, downscale=2)
    tr = Trainer(cfg, scene, None, method=FullMethod())
    capfd.readouterr()
    tr.run()  # no exception: generation, densification, training on the pseudo views
    err = capfd.readouterr().err
    assert tr.step == 16 and "Traceback" not in err
    assert all(torch.isfinite(p).all() for p in tr.model.params.values())
    method = tr.method
    row = method.history[1]
    assert row["cycle"] == 1 and row["added"] >= 0 and row["pseudo_trajectories"] == 2
    cams = method.pseudo_cams
    interior = 2 * (n_frames - 2)  # 2 trajectories between the 3 inputs
    for c in cams:
        assert torch.isfinite(c.image).all() and float(c.image.min()) >= 0 and float(c.image.max()) <= 1
    nan_lines = [ln for ln in err.splitlines() if "non-finite" in ln]
    if kind == "nan":  # frames 1 and N-2 of each trajectory are dropped, said once
        assert len(cams) == interior - 4 and len(nan_lines) == 1
        assert not any(c.name.endswith(("_001", f"_{n_frames - 2:03d}")) for c in cams)
    else:
        assert len(cams) == interior and not nan_lines
