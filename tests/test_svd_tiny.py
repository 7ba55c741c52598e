"""The svd backend on a tiny, randomly initialised Stable Video Diffusion of the real architectures.

The tiny UNetSpatioTemporalConditionModel / AutoencoderKLTemporalDecoder / CLIPVisionModelWithProjection
are saved with ``save_pretrained`` in the Hugging Face repository's layout and loaded back through
``SVDBackend.from_pretrained`` (the production loading code). Checks: the missing-weights error, the
backend + sampler against diffusers' own ``StableVideoDiffusionPipeline`` on the same noise (unguided,
one pass: conditioning, classifier-free guidance, EDM preconditioning and Euler steps must agree), and
the full uncertainty-modulated bidirectional sampler on 4 frames of 32x32 (its time is printed).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

diffusers = pytest.importorskip("diffusers", reason="the svd backend needs diffusers (pip install 'warpgs[svd]')")
transformers = pytest.importorskip("transformers", reason="the svd backend needs transformers (pip install 'warpgs[svd]')")

from warpgs.pseudo.backends import SVD_ENV, SVD_REPO, SVDBackend, SVDConfig, SVDWeightsNotFound  # noqa: E402
from warpgs.pseudo.sampler import SamplerConfig, karras_sigmas, sample_video  # noqa: E402


N, S = 4, 32  # frames, pixels


def build_tiny_svd(out):
    """Tiny random SVD components saved in the Hugging Face layout under ``out``."""
    from transformers import CLIPImageProcessor, CLIPVisionConfig, CLIPVisionModelWithProjection

    torch.manual_seed(0)
    unet = diffusers.UNetSpatioTemporalConditionModel(
        sample_size=16, in_channels=8, out_channels=4,
        down_block_types=("CrossAttnDownBlockSpatioTemporal", "DownBlockSpatioTemporal"),
        up_block_types=("UpBlockSpatioTemporal", "CrossAttnUpBlockSpatioTemporal"),
        block_out_channels=(32, 64), layers_per_block=1, cross_attention_dim=32, num_attention_heads=(2, 4),
        addition_time_embed_dim=8, projection_class_embeddings_input_dim=24,  # 3 x 8: fps, motion, noise aug
        num_frames=N,
    )
    vae = diffusers.AutoencoderKLTemporalDecoder(
        in_channels=3, out_channels=3, down_block_types=("DownEncoderBlock2D", "DownEncoderBlock2D"),
        block_out_channels=(32, 64), layers_per_block=1, latent_channels=4,
    )
    # the pipeline resizes the conditioning image to 224 x 224 for CLIP: a large patch keeps it tiny
    clip = CLIPVisionModelWithProjection(CLIPVisionConfig(
        hidden_size=32, projection_dim=32, num_hidden_layers=2, num_attention_heads=4, intermediate_size=37,
        image_size=224, patch_size=56))
    scheduler = diffusers.EulerDiscreteScheduler(
        prediction_type="v_prediction", beta_schedule="scaled_linear", beta_start=0.00085, beta_end=0.012,
        use_karras_sigmas=True, sigma_min=0.002, sigma_max=700.0, timestep_spacing="leading",
        timestep_type="continuous", steps_offset=1, interpolation_type="linear", num_train_timesteps=1000)
    pipe = diffusers.StableVideoDiffusionPipeline(vae=vae, image_encoder=clip, unet=unet, scheduler=scheduler,
                                                  feature_extractor=CLIPImageProcessor(crop_size=224, size=224))
    pipe.save_pretrained(out)
    return out


@pytest.fixture(scope="module")
def svd_dir(tmp_path_factory):
    return build_tiny_svd(tmp_path_factory.mktemp("svd") / "stable-video-diffusion-tiny")


@pytest.fixture(scope="module")
def backend(svd_dir):
    return SVDBackend.from_pretrained(svd_dir, device="cpu", cfg=SVDConfig(width=S, height=S, decode_chunk_size=N))


def _image(seed):
    rng = np.random.default_rng(seed)
    return (rng.random((S, S, 3)) * 255).astype(np.uint8)


def test_hf_layout_and_loading(svd_dir, backend):
    for sub in ("model_index.json", "unet", "vae", "image_encoder", "scheduler", "feature_extractor"):
        assert (svd_dir / sub).exists(), sub
    assert backend.dtype == torch.float32  # fp32 on the CPU (fp16 is for CUDA)
    assert backend.latent_shape(S, S) == (4, S // 2, S // 2)  # two VAE blocks: downsampling by 2
    # without width and height: the frames' aspect at about pseudo.svd.area pixels, in multiples of 8 x 2
    sized = SVDBackend(backend.unet, backend.vae, backend.image_encoder, backend.scheduler, SVDConfig(area=64 * 64))
    assert sized.model_size(60, 120) == (48, 96)  # 60 x 120 x (4096 / 7200): 45.3 x 90.5, rounded to 16s
    # match_frames: frames with fewer pixels than area keep their own (never fewer than min_area); off: area's
    own = SVDBackend(backend.unet, backend.vae, backend.image_encoder, backend.scheduler,
                     SVDConfig(area=64 * 64, min_area=32 * 32))
    assert own.model_size(32, 64) == (32, 64)  # 2,048 pixels: kept
    assert own.model_size(16, 16) == (32, 32)  # 256 < min_area: 1,024 pixels
    assert own.model_size(60, 120) == (48, 96)  # more than area: area's, as without match_frames
    upsampled = SVDBackend(backend.unet, backend.vae, backend.image_encoder, backend.scheduler,
                           SVDConfig(area=64 * 64, min_area=32 * 32, match_frames=False))
    assert upsampled.model_size(32, 64) == (48, 96)  # 4,096 pixels at the frames' 1:2
    # the scheduler's sigmas are EDM's Karras schedule between SVD's sigma_min and sigma_max
    assert torch.allclose(backend.sigmas(7, "cpu"), karras_sigmas(7, 0.002, 700.0), rtol=1e-5)
    assert backend.init_noise_sigma(backend.sigmas(7, "cpu")) == pytest.approx((700.0**2 + 1) ** 0.5, rel=1e-5)


def test_missing_weights_error_names_the_download(tmp_path, monkeypatch):
    monkeypatch.delenv(SVD_ENV, raising=False)
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    with pytest.raises(SVDWeightsNotFound) as e:
        SVDBackend.from_pretrained(None)
    msg = str(e.value)
    assert SVD_REPO in msg and SVD_ENV in msg and "--svd-path" in msg and "empty_cache" in msg
    assert "\n" not in msg  # one line under error:
    (tmp_path / "partial" / "unet").mkdir(parents=True)
    with pytest.raises(SVDWeightsNotFound) as e:
        SVDBackend.from_pretrained(tmp_path / "partial")
    assert "model_index.json" in str(e.value) and "vae" in str(e.value) and SVD_REPO in str(e.value)


def test_matches_diffusers_pipeline(svd_dir, backend):
    """Unguided, forward pass only: the sampler + backend reproduce StableVideoDiffusionPipeline."""
    from PIL import Image

    pipe = diffusers.StableVideoDiffusionPipeline.from_pretrained(svd_dir)
    pipe.set_progress_bar_config(disable=True)
    img = _image(0)
    noise = torch.randn(1, N, 4, S // 2, S // 2, generator=torch.Generator().manual_seed(1))
    ref = pipe(Image.fromarray(img), height=S, width=S, num_frames=N, num_inference_steps=3, min_guidance_scale=1.0,
               max_guidance_scale=3.0, fps=7, motion_bucket_id=127, noise_aug_strength=0.02,
               generator=torch.Generator().manual_seed(2), latents=noise.clone(), output_type="pt",
               decode_chunk_size=N).frames[0].permute(0, 2, 3, 1)
    out = sample_video(backend, torch.from_numpy(img).float() / 255.0, n_frames=N,
                       cfg=SamplerConfig(steps=3, guided=False, bidirectional=False), noise=noise[0],
                       generator=torch.Generator().manual_seed(2))  # same noise-augmentation draw
    assert out.frames.shape == (N, S, S, 3)
    assert torch.allclose(out.frames, ref, atol=1e-4), float((out.frames - ref).abs().max())


def guided_inputs():
    """(start, end, guidance, U): two random images, the guidance blending them, its right half unreliable."""
    start = torch.from_numpy(_image(3)).float() / 255.0
    end = torch.from_numpy(_image(4)).float() / 255.0
    w = torch.linspace(0, 1, N).view(N, 1, 1, 1)
    U = torch.zeros(N, S, S)
    U[:, :, S // 2:] = 0.9  # right half unreliable: no fusion there
    return start, end, (1 - w) * start + w * end, U


def test_modulated_bidirectional_sampler(backend):
    start, end, guidance, U = guided_inputs()
    cfg = SamplerConfig(steps=4, bidirectional=True, guided=True, b=-1.0, k=0.0)  # guidance on at every step
    t = time.perf_counter()
    out = sample_video(backend, start, end, guidance=guidance, uncertainty=U, cfg=cfg,
                       generator=torch.Generator().manual_seed(0))
    elapsed = time.perf_counter() - t
    print(f"\ntiny SVD: modulated bidirectional sampler, {N} frames {S}x{S}, 4 steps: {elapsed:.2f} s")
    assert out.frames.shape == (N, S, S, 3) and torch.isfinite(out.frames).all()
    assert float(out.frames.min()) >= 0.0 and float(out.frames.max()) <= 1.0
    assert out.guided_steps.tolist() == [4] * N
    # where U = 0 the last step's x0 is (x0_hat + g/eps)/(1 + 1/eps) and sigma_next = 0: the latents land
    # on the encoded guidance; where U > delta nothing pulls them there
    g_lat = backend.encode(guidance)
    left, right = slice(0, S // 4 - 1), slice(S // 4 + 1, S // 2)  # latent columns away from the U edge
    err_left = (out.latents[..., left] - g_lat[..., left]).abs().max()
    err_right = (out.latents[..., right] - g_lat[..., right]).abs().mean()
    assert err_left < 2e-2 * g_lat.abs().max(), float(err_left)
    assert err_right > 10 * err_left
    unguided = sample_video(backend, start, end, guidance=guidance, uncertainty=U,
                            cfg=SamplerConfig(steps=4, guided=False), generator=torch.Generator().manual_seed(0))
    assert unguided.guided_steps.sum() == 0
    assert (unguided.latents[..., left] - g_lat[..., left]).abs().mean() > 10 * err_left
