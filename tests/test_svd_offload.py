"""The svd backend's memory options and batching on the tiny random Stable Video Diffusion (CPU).

Each option must give the frames of the plain path (``offload: none``, every pass its own UNet call) within
floating-point tolerance: ``model`` and ``sequential`` offload (components on the device only for their stage,
one UNet half a call, chunked feed-forward, VAE encoder chunks of 1), the forward and backward passes batched into one
UNet call, and smaller VAE chunks for the encoder. Loading prints nothing.
"""

from __future__ import annotations

import pytest
import torch

pytest.importorskip("diffusers", reason="the svd backend needs diffusers (pip install 'warpgs[svd]')")
pytest.importorskip("transformers", reason="the svd backend needs transformers (pip install 'warpgs[svd]')")

from test_svd_tiny import N, S, build_tiny_svd, guided_inputs  # noqa: E402

from warpgs.pseudo.backends import SVDBackend, SVDConfig  # noqa: E402
from warpgs.pseudo.sampler import SamplerConfig, sample_video  # noqa: E402


@pytest.fixture(scope="module")
def svd_dir(tmp_path_factory):
    return build_tiny_svd(tmp_path_factory.mktemp("svd") / "tiny")


def load(svd_dir, **kw):
    return SVDBackend.from_pretrained(svd_dir, device="cpu", cfg=SVDConfig(width=S, height=S, **kw))


class OnePassAtATime:
    """The independent reference: the backend without its batched calls, so the sampler calls ``condition``
    and ``denoise`` once per pass."""

    def __init__(self, backend):
        self.b = backend
        self.default_noise_scale = backend.default_noise_scale

    def __getattr__(self, name):
        if name in ("condition_batch", "denoise_batch"):
            raise AttributeError(name)
        return getattr(self.b, name)


def trajectory(backend):
    start, end, guidance, U = guided_inputs()
    cfg = SamplerConfig(steps=3, bidirectional=True, guided=True)
    return sample_video(backend, start, end, guidance=guidance, uncertainty=U, cfg=cfg,
                        generator=torch.Generator().manual_seed(0))


@pytest.fixture(scope="module")
def reference(svd_dir):
    return trajectory(OnePassAtATime(load(svd_dir, offload="none", unet_batch_frames=N, encode_chunk_size=N,
                                          decode_chunk_size=N)))


@pytest.mark.parametrize("options", [
    dict(offload="none"),  # the defaults: both passes and both guidance halves in one UNet call
    dict(offload="none", encode_chunk_size=1),
    dict(offload="model"),
    dict(offload="sequential"),
])
def test_options_give_the_plain_paths_frames(svd_dir, reference, options):
    backend = load(svd_dir, **options)
    calls = []
    backend.unet.register_forward_pre_hook(lambda m, a, kw: calls.append((a[0].shape[0], set(backend.active))),
                                           with_kwargs=True)
    out = trajectory(backend)
    err = float((out.latents - reference.latents).abs().max())
    assert err < 1e-4, err
    assert (out.frames - reference.frames).abs().max() < 1e-4
    batch = {"none": 4, "model": 4, "sequential": 1}[options["offload"]]  # 2 passes x 2 guidance halves
    assert {b for b, _ in calls} == {batch} and len(calls) == 3 * 4 // batch
    if options["offload"] != "none":  # the UNet alone on the device while it runs
        assert all(active == {"unet"} for _, active in calls)
    assert set(out.times) == {"conditioning_s", "encode_s", "denoise_s", "decode_s"}
    assert all(v >= 0 for v in out.times.values())


def test_channels_last_gives_the_same_frames(svd_dir, reference):
    """pseudo.svd.channels_last (on CUDA): the UNet's 2-D convolutions in channels-last layout, its 5-D temporal
    ones left; applied here on the CPU by hand."""
    from warpgs.pseudo.backends import channels_last_convs

    backend = load(svd_dir)
    assert channels_last_convs(backend.unet) > 0
    convs = [m for m in backend.unet.modules() if isinstance(m, torch.nn.Conv2d)]
    assert all(m.weight.is_contiguous(memory_format=torch.channels_last) for m in convs)
    assert any(p.dim() == 5 for p in backend.unet.parameters())  # the temporal layers are there, untouched
    out = trajectory(backend)
    assert float((out.latents - reference.latents).abs().max()) < 1e-4


def test_unet_batch_limit_splits_the_calls(svd_dir, reference):
    """unet_batch_frames = 2 N: two rows (N frames each) a call, two calls a step."""
    backend = load(svd_dir, unet_batch_frames=2 * N)
    sizes = []
    backend.unet.register_forward_pre_hook(lambda m, a: sizes.append(a[0].shape[0]))
    out = trajectory(backend)
    assert sizes == [2] * 6
    assert torch.allclose(out.latents, reference.latents, atol=1e-4)


def test_offload_moves_each_component_for_its_stage(svd_dir):
    backend = load(svd_dir, offload="model")
    seen = {}
    for name in ("image_encoder", "vae", "unet"):
        getattr(backend, name).register_forward_pre_hook(
            lambda m, a, name=name: seen.setdefault(name, set()).add(frozenset(backend.active)))
    backend.vae.decoder.register_forward_pre_hook(lambda m, a: seen.setdefault("decoder", set()).add(
        frozenset(backend.active)))
    backend.vae.encoder.register_forward_pre_hook(lambda m, a: seen.setdefault("encoder", set()).add(
        frozenset(backend.active)))
    trajectory(backend)
    assert seen["image_encoder"] == {frozenset({"image_encoder"})}
    assert seen["encoder"] == {frozenset({"vae"})} and seen["decoder"] == {frozenset({"vae"})}
    assert seen["unet"] == {frozenset({"unet"})}
    with pytest.raises(ValueError, match="offload"):
        SVDBackend(backend.unet, backend.vae, backend.image_encoder, backend.scheduler, SVDConfig(offload="disk"))


def test_loading_prints_nothing_and_attention_is_sdpa(svd_dir, capfd):
    from diffusers.models.attention_processor import AttnProcessor2_0

    capfd.readouterr()
    backend = load(svd_dir)
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out, err)
    # and in a fresh process, where the libraries' say-once advice has not been said yet
    import subprocess
    import sys

    code = ("from warpgs.pseudo.backends import SVDBackend, SVDConfig; "
            f"SVDBackend.from_pretrained({str(svd_dir)!r}, cfg=SVDConfig(width={S}, height={S}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       cwd=__import__("pathlib").Path(__file__).resolve().parents[1])
    assert r.returncode == 0 and r.stdout == "" and r.stderr == "", (r.stdout, r.stderr)
    # torch's scaled_dot_product_attention (flash / memory-efficient kernels on CUDA) in every attention layer
    procs = backend.unet.attn_processors
    assert procs and all(isinstance(p, AttnProcessor2_0) for p in procs.values())


def test_half_precision_encoder_retries_an_overflowing_chunk_in_float32(svd_dir, monkeypatch):
    """The VAE encoder runs in the model's dtype; a chunk whose latents come out non-finite (float16 overflow) is
    encoded again in float32 and the VAE is back in its dtype after. Reference: the same weights' float32 encode."""
    backend = load(svd_dir, encode_chunk_size=2)
    x = torch.rand(N, 3, S, S, generator=torch.Generator().manual_seed(5)) * 2 - 1
    with torch.no_grad():  # chunk 1 in float32, chunk 2 from float16 input
        ref = torch.cat([backend.vae.encode(x[:2]).latent_dist.mode(),
                         backend.vae.encode(x[2:].half().float()).latent_dist.mode()])
    encode, dtypes = backend.vae.encode, []

    def overflowing(images, *a, **kw):  # float16 overflows on the first chunk only
        dtypes.append(images.dtype)
        out = encode(images.float() if images.dtype == torch.float16 else images, *a, **kw)
        if images.dtype == torch.float16 and len(dtypes) == 1:
            out.latent_dist.mean[0, 0, 0, 0] = float("inf")
        return out

    monkeypatch.setattr(backend.vae, "encode", overflowing)
    # the CPU lacks some float16 kernels: the VAE computes in float32 and says float16, as it would on CUDA
    monkeypatch.setattr(type(backend.vae), "dtype", property(lambda m: dtypes_state["dtype"]), raising=False)
    dtypes_state = {"dtype": torch.float16}
    monkeypatch.setattr(backend, "_vae_dtype", lambda dt: dtypes_state.update(dtype=dt))
    lat = backend._vae_encode(x)
    assert dtypes == [torch.float16, torch.float32, torch.float16]  # chunk 1, its float32 retry, chunk 2
    assert dtypes_state["dtype"] == torch.float16  # back in its dtype
    assert torch.isfinite(lat).all() and torch.allclose(lat, ref, atol=1e-5)


@pytest.mark.parametrize("n,size", [(9, 4), (25, 4), (25, 8), (4, 4), (1, 4), (5, 1), (7, 100)])
def test_even_chunks_cover_the_frames_in_near_equal_parts(n, size):
    from warpgs.pseudo.backends import even_chunks

    parts = even_chunks(n, size)
    lengths = [p.stop - p.start for p in parts]
    assert [i for p in parts for i in range(p.start, p.stop)] == list(range(n))  # in order, each frame once
    assert len(parts) == -(-n // size) and max(lengths) <= size and max(lengths) - min(lengths) <= 1
