"""Warp <-> torch plumbing: one place that initialises Warp, maps devices and wraps tensors zero-copy."""

from __future__ import annotations

import functools

import torch
import warp as wp

try:  # the ctypes descriptor Warp passes to kernels; private, so fall back to the public route
    from warp._src.types import array_t
except ImportError:  # pragma: no cover - other Warp versions
    array_t = None

from warpgs.console import filtered_stderr

# Warp's start-up banner and per-module load lines are noise for users; keep warnings (errors only on
# machines without CUDA).
wp.config.log_level = wp.LOG_WARNING if torch.cuda.is_available() else wp.LOG_ERROR
# printed by Warp's native start-up on every machine without an NVIDIA driver
NO_DRIVER_WARNING = "could not find or load the nvidia cuda driver"


@functools.cache
def _init() -> None:
    """``wp.init()``, once. Where torch sees no CUDA device, Warp's native line saying that it found no
    CUDA driver is dropped: such a machine runs on the CPU anyway (a run that asks for cuda there stops
    with its own error), so the warning does not apply. Everything else Warp prints stays."""
    if torch.cuda.is_available():
        wp.init()
        return
    with filtered_stderr([NO_DRIVER_WARNING]):
        wp.init()


def init() -> None:
    """Initialises Warp (``_init``); every warpgs module calls this rather than ``wp.init``."""
    _init()


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
    """A Warp array viewing a contiguous torch tensor (no copy). ``dtype`` groups trailing dims (wp.vec3...)."""
    if not t.is_contiguous():
        raise ValueError("to_wp needs a contiguous tensor")
    return wp.from_torch(t, dtype=dtype, requires_grad=False)



def arg(t: torch.Tensor, dtype=None):
    """A kernel-argument descriptor of a contiguous torch tensor: the same zero-copy view as ``to_wp``,
    built directly (about 10x cheaper per launch argument). The descriptor holds a reference to the
    tensor, so a temporary passed straight into a launch's argument list stays alive until the launch
    is enqueued (later reuse of its memory by torch's allocator is ordered after it on the stream)."""
    if not t.is_contiguous():
        raise ValueError("kernel arguments must be contiguous tensors")
    if array_t is None:  # pragma: no cover
        d = wp.from_torch(t, dtype=dtype, requires_grad=False, return_ctype=True)
    else:
        k = len(getattr(dtype, "_shape_", ()))  # trailing tensor dims one element spans (vec3: 1, mat44: 2)
        nd = t.dim() - k
        es = t.element_size()
        d = array_t(t.data_ptr(), 0, nd, t.shape[:nd], [s * es for s in t.stride()[:nd]])
    d._owner = t
    return d


def struct_arg(struct, **fields):
    """An instance of the ``@wp.struct`` class ``struct`` with ``fields`` set, for a kernel argument.

    A torch tensor given for an array field becomes the same zero-copy descriptor as ``arg`` (the field's
    dtype groups trailing dims), written straight into the instance's native struct: Warp's own field
    setter accepts only a ``wp.array``, and wrapping each tensor in one (``to_wp``) costs several times
    more per launch. Reading such a field back in Python gives None; kernels see the tensor. Other
    values are set as Warp sets them. The instance holds references to its tensors, as ``arg``'s
    descriptors do."""
    inst = struct()
    tensors = []
    for name, value in fields.items():
        if not isinstance(value, torch.Tensor):
            setattr(inst, name, value)
            continue
        field = struct.vars[name].type
        if array_t is None:  # pragma: no cover - other Warp versions
            setattr(inst, name, to_wp(value, field.dtype))
        else:
            d = arg(value, field.dtype)
            if d.ndim != field.ndim:
                raise ValueError(f"struct field {name!r} takes a {field.ndim}-d array of {field.dtype.__name__}, "
                                 f"got a tensor of shape {tuple(value.shape)}")
            setattr(inst._ctype, name, d)
        tensors.append(value)
    inst.__dict__["_tensors"] = tensors  # StructInstance.__setattr__ admits only the struct's fields
    return inst


def launch(kernel, dim, inputs, device: str, stream=None) -> None:
    _init()
    if (isinstance(dim, int) and dim == 0) or (not isinstance(dim, int) and 0 in dim):
        return
    wp.launch(kernel, dim=dim, inputs=inputs, device=device, stream=stream)
