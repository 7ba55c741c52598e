"""Warp <-> torch plumbing: one place that initialises Warp, maps devices and wraps tensors zero-copy."""

from __future__ import annotations

import functools

import torch
import warp as wp

# Warp's start-up banner and per-module load lines are noise for users; keep warnings (errors only on
# machines without CUDA, where Warp warns that no driver was found).
wp.config.log_level = wp.LOG_WARNING if torch.cuda.is_available() else wp.LOG_ERROR


@functools.cache
def _init() -> None:
    wp.init()


def device_of(t: torch.Tensor) -> str:
    """The Warp device name of a torch tensor ('cpu' or 'cuda:N')."""
    _init()
    if t.device.type == "cpu":
        return "cpu"
    if t.device.type == "cuda":
        return f"cuda:{t.device.index if t.device.index is not None else torch.cuda.current_device()}"
    raise ValueError(f"warpgs runs on cpu or cuda tensors, got a tensor on {t.device}")


def stream_of(device: str):
    """Warp stream wrapping torch's current stream, so Warp kernels and torch ops stay ordered."""
    if device == "cpu":
        return None
    return _stream(device, torch.cuda.current_stream(torch.device(device)).cuda_stream)


@functools.lru_cache(maxsize=16)
def _stream(device: str, handle: int):
    return wp.Stream(device, cuda_stream=handle)


def to_wp(t: torch.Tensor, dtype=None) -> wp.array:
    """A Warp view of a contiguous torch tensor (no copy). ``dtype`` groups trailing dims (e.g. wp.vec3)."""
    if not t.is_contiguous():
        t = t.contiguous()
    return wp.from_torch(t, dtype=dtype, requires_grad=False)


def launch(kernel, dim, inputs, device: str, stream=None) -> None:
    if (isinstance(dim, int) and dim == 0) or (not isinstance(dim, int) and 0 in dim):
        return
    wp.launch(kernel, dim=dim, inputs=inputs, device=device, stream=stream)
