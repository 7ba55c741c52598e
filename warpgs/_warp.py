"""Warp <-> torch plumbing: one place that initialises Warp, maps devices and wraps tensors zero-copy."""

from __future__ import annotations

import functools
import math
import os
import threading

import torch
import warp as wp

try:  # the ctypes descriptor Warp passes to kernels; private, so fall back to the public route
    from warp._src.types import array_t
except ImportError:  # pragma: no cover - other Warp versions
    array_t = None
try:  # the class of @wp.struct types (private; the fast launch path needs it to walk a struct's fields)
    from warp._src.codegen import Struct as _WarpStruct
except ImportError:  # pragma: no cover - other Warp versions
    from warp.codegen import Struct as _WarpStruct
try:  # Warp's module of the runtime (its ``runtime`` is set by wp.init) and its launch-failure error (private:
    # the direct CUDA launch below needs them; without them every launch goes through ``wp.Launch.launch``)
    import warp._src.context as _wp_context
    from warp._src.context import _raise_cuda_launch_error
except ImportError:  # pragma: no cover - other Warp versions
    _wp_context = _raise_cuda_launch_error = None

# torch's current CUDA stream of a device as its raw handle (an int), without building a torch.cuda.Stream
# (private; CUDA builds of torch only): one call instead of ``torch.cuda.current_stream(...).cuda_stream``
_current_raw_stream = getattr(torch._C, "_cuda_getCurrentRawStream", None)

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


@functools.cache
def native_function(name: str):
    """A function of Warp's native library by name (private API), or None where this Warp has none; looked up
    once per name."""
    _init()
    try:
        from warp._src.context import runtime
    except ImportError:  # pragma: no cover - other Warp versions
        return None
    return getattr(getattr(runtime, "core", None), name, None)


def init() -> None:
    """Initialises Warp (``_init``); every warpgs module calls this rather than ``wp.init``."""
    _init()


_DEVICE_NAMES: dict = {}  # torch.device -> Warp device name, filled by ``_device_name``


def device_of(t: torch.Tensor) -> str:
    """The Warp device name of a torch tensor ('cpu' or 'cuda:N'); looked up once per torch device."""
    d = t.device
    name = _DEVICE_NAMES.get(d)
    return _device_name(d) if name is None else name


def _device_name(d: torch.device) -> str:
    """``device_of``'s name of torch device ``d``, remembered (after ``_init``) where it is fixed: every device but
    a CUDA one without an index (whose name follows torch's current device)."""
    _init()
    if d.type == "cpu":
        name = "cpu"
    elif d.type == "cuda":
        if d.index is None:
            return f"cuda:{torch.cuda.current_device()}"
        name = f"cuda:{d.index}"
    else:
        raise ValueError(f"warpgs runs on cpu or cuda tensors, got a tensor on {d}")
    _DEVICE_NAMES[d] = name
    return name


def stream_of(device: str):
    """Warp stream wrapping torch's current stream, so Warp kernels and torch ops stay ordered."""
    if device == "cpu":
        return None
    return _stream(device, torch.cuda.current_stream(torch.device(device)).cuda_stream)


@functools.lru_cache(maxsize=16)
def _stream(device: str, handle: int):
    return wp.Stream(device, cuda_stream=handle)


def wp_stream(device: str, stream):
    """``stream`` as Warp's Python API takes it: a raw handle (an int, ``launch_stream``) of CUDA device ``device``
    as the wp.Stream wrapping it (``stream_of``'s), anything else (None, a wp.Stream) as it is."""
    return _stream(device, stream) if type(stream) is int else stream


def launch_stream(t: torch.Tensor):
    """The stream argument for ``Launcher``/``fast_launch`` (and ``native_on_stream``) of launches on torch
    tensor ``t``'s device: None on the CPU; on CUDA, torch's current stream there as its raw handle (an int),
    which the launcher passes to the driver directly, or, where torch has no raw-handle lookup,
    ``stream_of``'s wp.Stream. Either way the same stream as ``stream_of(device_of(t))``: one lookup per render
    serves its forward launches, and kept on the autograd context, its backward's (autograd runs a custom
    Function's backward on the stream its forward ran on)."""
    d = t.device
    if d.type == "cpu":
        return None
    if _current_raw_stream is None:  # pragma: no cover - torch builds without CUDA have no CUDA tensors
        return stream_of(device_of(t))
    return _current_raw_stream(d.index if d.index is not None else torch.cuda.current_device())


def native_on_stream(device: str, stream, fn, *args) -> bool:
    """Calls the native Warp function ``fn(*args)`` with raw stream handle ``stream`` as the current stream of
    Warp's context of CUDA device ``device`` (where Warp's native sorts and scans enqueue their work), as
    ``wp.ScopedStream(stream, sync_enter=False)`` would, without its Python: the device's context is made
    current, the context's stream set without a wait on the previous one, and both restored afterwards
    (also on an error; the stream, like ScopedStream's exit, without a wait). Returns False, calling nothing,
    where that cannot be done this way (``stream`` not an int handle, a Warp graph capture under way, whose
    bookkeeping needs Warp's own route, or a Warp without these private functions): the caller then uses
    ``wp.ScopedStream``."""
    if type(stream) is not int:
        return False
    runtime = _native_runtime()
    if runtime is None or runtime.captures:
        return False
    core = runtime.core
    ctx = _cuda_context(device)
    core.wp_cuda_context_push_current(ctx)
    try:
        previous = core.wp_cuda_context_get_stream(ctx)
        core.wp_cuda_context_set_stream(ctx, stream, 0)
        try:
            fn(*args)
        finally:
            core.wp_cuda_context_set_stream(ctx, previous, 0)
    finally:
        core.wp_cuda_context_pop_current()
    return True


_NATIVE_NAMES = ("wp_cuda_launch_kernel", "wp_cuda_context_push_current", "wp_cuda_context_pop_current",
                 "wp_cuda_context_get_stream", "wp_cuda_context_set_stream")


@functools.cache
def _native_runtime():
    """Warp's runtime where it has everything the direct CUDA paths (``Launcher``, ``native_on_stream``) use:
    its graph captures (``captures``) and the native functions ``_NATIVE_NAMES``; None otherwise (another Warp
    version), and those paths go through Warp's Python instead."""
    _init()
    if _wp_context is None or _raise_cuda_launch_error is None:  # pragma: no cover - other Warp versions
        return None
    runtime = getattr(_wp_context, "runtime", None)
    core = getattr(runtime, "core", None)
    if not isinstance(getattr(runtime, "captures", None), dict) or not all(hasattr(core, n) for n in _NATIVE_NAMES):
        return None  # pragma: no cover - other Warp versions
    return runtime


@functools.cache
def _cuda_context(device: str):
    """Warp's CUDA context of ``device`` (its ``Device.context``)."""
    _init()
    return wp.get_device(device).context


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


def no_threads(dim) -> bool:
    """Whether a launch of ``dim`` (an int or a tuple of them) runs no thread at all."""
    return dim == 0 if isinstance(dim, int) else 0 in dim


def launch(kernel, dim, inputs, device: str, stream=None) -> None:
    _init()
    if no_threads(dim):
        return
    wp.launch(kernel, dim=dim, inputs=inputs, device=device, stream=stream)


# ----------------------------------------------------------------------------------------------------
# the fast launch path: one recorded ``wp.Launch`` per (kernel, device), its packed parameters
# rewritten in place from torch tensors and Python numbers on every call

_TORCH_OF_WARP = {wp.float32: torch.float32, wp.int32: torch.int32, wp.int64: torch.int64,
                  wp.uint32: torch.int32, wp.uint64: torch.int64, wp.float64: torch.float64,
                  wp.int8: torch.int8, wp.uint8: torch.uint8, wp.float16: torch.float16,
                  float: torch.float32, int: torch.int32}


def _array_setter(label: str, atype, c):
    """Writes a torch tensor into the array descriptor ``c`` (in place) for a kernel argument of Warp
    array type ``atype``: its data pointer, shape and byte strides, after checking that the tensor
    has the argument's scalar type and number of dimensions (trailing ones grouped by a vector or
    matrix dtype) and is contiguous. A wrong tensor raises a ValueError naming the argument.

    The descriptor holds the same numbers as one built from the tensor's own shape and strides, written with
    fewer calls into torch: of a contiguous tensor whose first dimension has more than one entry, the first
    stride is the product of the other sizes (torch's contiguity rule; ``inner``, fixed per argument, has no 0),
    so a one-dimensional array argument reads the stride only where the first size is 0 or 1, and its shape
    and stride are rewritten only when the first size changed (the descriptor is this launcher's own)."""
    dtype = atype.dtype
    inner = tuple(getattr(dtype, "_shape_", ()))
    scalar = getattr(dtype, "_wp_scalar_type_", dtype)
    want = _TORCH_OF_WARP.get(scalar)
    nd = atype.ndim
    full = nd + len(inner)
    es = torch.empty((), dtype=want).element_size() if want is not None else 0
    c.ndim = nd
    shape, strides = c.shape, c.strides

    def fail(t):
        raise ValueError(f"kernel argument {label!r} takes a contiguous {want} tensor of "
                         f"{nd} dimension(s)" + (f" followed by {list(inner)}" if inner else "")
                         + f", got {t.dtype} {list(t.shape)}" + ("" if t.is_contiguous() else " (not contiguous)"))

    if nd == 1 and 0 not in inner:
        row = math.prod(inner) * es  # the first stride's bytes of a contiguous tensor with more than one row
        written = -1  # the first size that ``shape``/``strides`` hold (-1: none yet, or one of 0 or 1 rows)

        def set_array(t):
            nonlocal written
            shp = t.shape
            if t.dtype is not want or len(shp) != full or shp[1:] != inner or not t.is_contiguous():
                fail(t)
            c.data = t.data_ptr()
            n = shp[0]
            if n != written:
                shape[0] = n
                if n > 1:
                    strides[0] = row
                    written = n
                else:
                    strides[0] = t.stride(0) * es
                    written = -1
        return set_array

    def set_array(t):
        shp = t.shape
        if t.dtype is not want or len(shp) != full or shp[nd:] != inner or not t.is_contiguous():
            fail(t)
        c.data = t.data_ptr()
        st = t.stride()
        for j in range(nd):
            shape[j] = shp[j]
            strides[j] = st[j] * es
    return set_array


def _scalar_setter(c):
    def set_scalar(v):
        c.value = v
    return set_scalar


class KeptFields(tuple):
    """Field values of a struct argument (a tuple, in the struct's field order) that a launcher keeps after writing
    them, so that given the same object again it writes nothing (``_struct_setter``). Only for values that are kept
    anyway and hold no tensor in an autograd graph: a launcher holds its last ones until it is given others, and an
    autograd graph kept alive past its step breaks the next step's CUDA graph capture (an AccumulateGrad node of an
    earlier step on another stream). ``warpgs.render._camera`` makes one per view."""

    __slots__ = ()


def _struct_setter(label: str, stype, c):
    """Writes a tuple of field values (torch tensors for array fields), in the struct's field order,
    into the struct's packed value ``c`` in place. Given the same ``KeptFields`` object as the call before, it writes
    nothing: ``c`` is this launcher's own and already holds those values (a tuple cannot change, and its tensors
    keep their memory). Other tuples are written every time and not kept."""
    fields = []
    for name, var in stype.vars.items():
        sub = getattr(c, name)  # a view into ``c``'s memory for arrays and nested structs
        if wp.types.is_array(var.type):
            fields.append(_array_setter(f"{label}.{name}", var.type, sub))
        elif isinstance(var.type, _WarpStruct):
            fields.append(_struct_setter(f"{label}.{name}", var.type, sub))
        else:
            fields.append(functools.partial(setattr, c, name))
    n_fields = len(fields)
    last = None  # the KeptFields written last (a reference: no other object can have its address meanwhile)

    def set_struct(values):
        nonlocal last
        if values is last:
            return
        if len(values) != n_fields:
            raise ValueError(f"kernel argument {label!r} takes {n_fields} fields "
                             f"({', '.join(stype.vars)}), got {len(values)}")
        last = None  # a field that fails leaves ``c`` part written
        for f, v in zip(fields, values):
            f(v)
        last = values if type(values) is KeptFields else None
    return set_struct


class Launcher:
    """A kernel's launch on one device with its parameters packed once and rewritten in place.

    ``Launcher.of(kernel, device)(dim, stream, *args)`` launches ``kernel`` like ``launch`` does, but
    takes torch tensors directly for array arguments (their Warp dtype and dimensions come from the
    kernel's signature) and a tuple of field values for a struct argument; Python numbers for scalars.
    wp.launch packs every argument anew (type checks, a new descriptor per array); here each call
    only writes pointers, shapes and numbers into the recorded ``wp.Launch``'s parameter block, several
    times cheaper per launch, which is what a training step's dozen launches cost on the host.
    The tensors must stay alive until the call returns (they do: they are its arguments); torch's
    allocator orders later reuse of their memory after the launch on the stream.

    ``stream``: None (the CPU; on CUDA, Warp's current stream of the device), a ``wp.Stream``, or a raw CUDA
    stream handle (an int, ``launch_stream``). With a handle, a CUDA launch calls Warp's native launch
    (``wp_cuda_launch_kernel``) directly with the recorded launch's fields, the same call
    ``wp.Launch.launch`` makes without its per-launch Python (capture look-ups, the stream object); while a
    Warp graph capture is under way (``wp.capture_begin``), or where this Warp lacks the private names, it
    goes through ``wp.Launch.launch`` as before."""

    _local = threading.local()  # launchers per thread: two threads never share a parameter block

    @classmethod
    def of(cls, kernel, device: str) -> "Launcher":
        """This thread's launcher of ``kernel`` on ``device`` (a viewer serving two clients, or the parts of
        ``launch_parts``, launch from several threads at once)."""
        try:
            cache = cls._local.cache
        except AttributeError:
            cache = cls._local.cache = {}
        got = cache.get((kernel, device))
        if got is None:
            _init()
            got = cache[(kernel, device)] = cls(kernel, device)
        return got

    def __init__(self, kernel, device: str):
        self.kernel = kernel
        self.device = device
        self.cmd = wp.Launch(kernel, wp.get_device(device))
        self.dim = None
        setters = []
        for i, a in enumerate(kernel.adj.args):
            c = self.cmd.params[i + 1]
            if wp.types.is_array(a.type):
                # a descriptor of this launcher's own: wp.Launch's default is the annotation's cached one, which
                # every launcher of the kernel (and Warp itself, for a None argument) would share
                c = type(c)()
                self.cmd.set_param_at_index_from_ctype(i, c)
                setters.append(_array_setter(a.label, a.type, c))
            elif isinstance(a.type, _WarpStruct):
                setters.append(_struct_setter(a.label, a.type, c))
            elif hasattr(c, "value"):
                setters.append(_scalar_setter(c))
            else:  # vectors and matrices passed by value: Warp's own packing
                setters.append(functools.partial(self.cmd.set_param_at_index, i))
        self.setters = setters
        self.n_args = len(setters)
        self._runtime = self._native = None
        self._size = self.cmd.bounds.size
        self.is_cuda = self.cmd.device.is_cuda
        if self.is_cuda and not self.cmd.adjoint:
            self._runtime = _native_runtime()
            if self._runtime is not None:
                self._native = _native_launch(self.cmd, self._runtime.core.wp_cuda_launch_kernel)

    def __call__(self, dim, stream, *args) -> None:
        if len(args) != self.n_args:
            raise TypeError(f"kernel {self.kernel.key!r} takes {self.n_args} arguments, got {len(args)}")
        if (dim == 0) if isinstance(dim, int) else (0 in dim):  # ``no_threads``, inlined
            return
        for set_arg, a in zip(self.setters, args):
            set_arg(a)
        if dim != self.dim:
            self.cmd.set_dim(dim)
            self.dim = dim
            self._size = self.cmd.bounds.size  # set_dim made new launch bounds (and pointed the parameters at them)
        if type(stream) is int and self.is_cuda:
            if self._native is not None and not self._runtime.captures:
                self._native(self._size, stream)
                return
            stream = wp_stream(self.device, stream)  # Warp's own route takes a wp.Stream
        self.cmd.launch(stream)


def _native_launch(cmd, launch_kernel):
    """``f(size, stream)``: what ``cmd.launch(stream)`` (a recorded forward ``wp.Launch`` on a CUDA device) does
    outside graph captures, for a launch of ``size`` threads (``cmd.bounds.size``) on raw stream handle
    ``stream``: Warp's native launch with the launch's fields, raising Warp's error if it fails. The fields are
    read here once: none changes after the launch is made but the bounds, which ``set_dim`` replaces and points
    the first entry of ``params_addr`` (the same array, changed in place) at; the caller passes their size."""
    context, hooks = cmd.device.context, cmd.hooks
    fn, smem = hooks.forward, hooks.forward_smem_bytes
    max_blocks, block_dim, grid_stride, cluster_dim = cmd.max_blocks, cmd.block_dim, int(cmd.grid_stride), cmd.cluster_dim
    params_addr = cmd.params_addr

    def launch(size, stream):
        if launch_kernel(context, fn, size, max_blocks, block_dim, grid_stride, cluster_dim, smem, params_addr,
                         stream, None):
            _raise_cuda_launch_error(cmd.kernel, cmd.device, hooks, False)
    return launch


def fast_launch(kernel, dim, device: str, stream, *args) -> None:
    """``Launcher.of(kernel, device)(dim, stream, *args)`` (this thread's launcher looked up here directly)."""
    try:
        launcher = Launcher._local.cache[(kernel, device)]
    except (AttributeError, KeyError):
        launcher = Launcher.of(kernel, device)
    launcher(dim, stream, *args)


@functools.cache
def _part_pool(workers: int, pid: int):
    """The threads of ``launch_parts``, one pool per process (``pid``: a forked child has none of its
    parent's threads, so it makes its own)."""
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix="warpgs-cpu")


def cpu_cores() -> int:
    """The CPU cores this process may run on (read once per process: every CPU render asks, and the system call
    was 2% of a tiny render's host time)."""
    return _cpu_cores(os.getpid())


@functools.cache
def _cpu_cores(pid: int) -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _launch_here(kernel, device: str, dim, *args) -> None:
    """A CPU launch with the calling thread's launcher (in a pool thread, that thread's own)."""
    Launcher.of(kernel, device)(dim, None, *args)


def launch_parts(kernel, dim: int, device: str, n_parts: int, args_of_part) -> None:
    """Runs the CPU kernel ``kernel`` (taking ``part, n_parts`` as its last two arguments; ``dim``: the whole
    launch's threads) as ``n_parts`` launches of every n_parts-th thread, ``args_of_part(p)`` giving part p's
    other arguments. The parts run at the same time on threads of a pool where this process may use more
    than one core (a Warp CPU kernel runs on one thread and lets go of the GIL), else one after the other;
    either way each part computes the same thing."""
    if dim == 0:
        return
    per_part = (dim + n_parts - 1) // n_parts
    if n_parts == 1 or cpu_cores() < 2:
        for p in range(n_parts):
            _launch_here(kernel, device, per_part, *args_of_part(p), p, n_parts)
        return
    pool = _part_pool(n_parts - 1, os.getpid())
    futures = [pool.submit(_launch_here, kernel, device, per_part, *args_of_part(p), p, n_parts)
               for p in range(1, n_parts)]
    try:
        _launch_here(kernel, device, per_part, *args_of_part(0), 0, n_parts)
    finally:
        for f in futures:
            f.result()
