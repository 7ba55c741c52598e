"""The fast launch path (warpgs._warp.Launcher, launch_parts) against Warp's own wp.launch, and the CPU
compositing's parts: the same numbers on one core as on two."""

import pytest
import torch
import warp as wp

import warpgs._warp as W
from warpgs._warp import Launcher, fast_launch, launch_parts

W.init()


@wp.struct
class _Pair:
    a: wp.array(dtype=wp.vec3)
    scale: float


@wp.kernel
def _axpy(p: _Pair, x: wp.array2d(dtype=float), shift: int, out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    out[i, j] = p.scale * x[i, j] + p.a[i][j] + float(shift)


@wp.kernel
def _strided(x: wp.array(dtype=float), out: wp.array(dtype=float), part: int, n_parts: int):
    t = wp.tid() * n_parts + part
    if t >= x.shape[0]:
        return
    acc = float(0.0)
    for k in range(200):
        acc = acc + wp.sin(x[t] + float(k))
    out[t] = acc


def test_fast_launch_matches_wp_launch_with_structs_2d_arrays_and_scalars():
    g = torch.Generator().manual_seed(0)
    a, x = torch.rand(5, 3, generator=g), torch.rand(5, 3, generator=g)
    want = torch.zeros(5, 3)
    p = _Pair()
    p.a = wp.from_torch(a, dtype=wp.vec3)
    p.scale = 2.5
    wp.launch(_axpy, dim=(5, 3), inputs=[p, wp.from_torch(x), 7, wp.from_torch(want)], device="cpu")
    got = torch.zeros(5, 3)
    fast_launch(_axpy, (5, 3), "cpu", None, (a, 2.5), x, 7, got)
    assert torch.equal(got, want)
    assert torch.equal(want, 2.5 * x + a + 7)
    # a second call with other tensors and numbers rewrites every parameter (nothing stale from the first)
    a2, x2, got2 = torch.rand(4, 3, generator=g), torch.rand(4, 3, generator=g), torch.zeros(4, 3)
    fast_launch(_axpy, (4, 3), "cpu", None, (a2, -1.0), x2, 0, got2)
    assert torch.equal(got2, -1.0 * x2 + a2)
    assert torch.equal(got, want)  # the first call's output is untouched


def test_a_struct_given_as_the_same_kept_fields_again_is_not_rewritten_and_other_values_are():
    g = torch.Generator().manual_seed(1)
    a, b, x = torch.rand(4, 3, generator=g), torch.rand(4, 3, generator=g), torch.rand(4, 3, generator=g)
    first = W.KeptFields((a, 2.0))
    got = torch.zeros(4, 3)
    fast_launch(_axpy, (4, 3), "cpu", None, first, x, 0, got)
    assert torch.equal(got, 2.0 * x + a)
    a.add_(1.0)  # the same fields: the tensor's memory is read at the launch, as before
    fast_launch(_axpy, (4, 3), "cpu", None, first, x, 0, got)
    assert torch.equal(got, 2.0 * x + a)
    fast_launch(_axpy, (4, 3), "cpu", None, W.KeptFields((b, 2.0)), x, 0, got)  # equal-looking, another object
    assert torch.equal(got, 2.0 * x + b)
    fast_launch(_axpy, (4, 3), "cpu", None, (a, -1.0), x, 0, got)  # a plain tuple is written every time
    assert torch.equal(got, -1.0 * x + a)
    with pytest.raises(ValueError, match="'p.a'"):  # a failed write is not remembered as written
        fast_launch(_axpy, (4, 3), "cpu", None, W.KeptFields((a.double(), 1.0)), x, 0, got)
    fast_launch(_axpy, (4, 3), "cpu", None, first, x, 0, got)
    assert torch.equal(got, 2.0 * x + a)


def test_a_launcher_keeps_no_tensor_of_a_plain_tuple_alive():
    # a tensor of an autograd graph kept past its step keeps the graph (and its AccumulateGrad nodes) alive, which
    # breaks the next step's CUDA graph capture
    import gc
    import weakref

    leaf = torch.rand(4, 3, requires_grad=True)
    a = leaf * 2.0  # in a graph
    ref = weakref.ref(a)
    got = torch.zeros(4, 3)
    x = torch.rand(4, 3)
    fast_launch(_axpy, (4, 3), "cpu", None, (a, 1.0), x, 0, got)
    assert torch.equal(got, x + a.detach())
    del a
    gc.collect()
    assert ref() is None


def test_render_camera_tuple_is_made_once_per_view_and_follows_the_matrices_memory():
    from warpgs import render

    vm, K = torch.eye(4), torch.tensor([[10.0, 0, 8], [0, 10.0, 6], [0, 0, 1]])
    cam = render._camera(vm, K, 16, 12, 0.3, False)
    assert render._camera(vm, K, 16, 12, 0.3, False) is cam
    assert render._camera(vm.detach(), K, 16, 12, 0.3, False) is cam  # another tensor on the same memory
    assert render._camera(vm, K, 16, 12, 0.3, True) is not cam  # other numbers: another tuple
    assert render._camera(vm.clone(), K, 16, 12, 0.3, False) is not cam  # other memory: another tuple
    vm[0, 3] = 5.0  # changed in place: the tuple's view reads it
    assert float(cam[0][0, 0, 3]) == 5.0
    for k in range(render._CAMERAS_KEPT + 1):  # many views: the oldest go
        render._camera(torch.eye(4) * (k + 2), K, 16, 12, 0.3, False)
    assert len(render._CAMERAS) <= render._CAMERAS_KEPT
    assert render._camera(vm, K, 16, 12, 0.3, False) is not cam


@pytest.mark.parametrize("bad, why", [
    (lambda x: x.double(), "torch.float32"),          # wrong scalar type
    (lambda x: x[:, :2].contiguous(), r"followed by \[3\]"),  # a vec3 array needs a trailing 3
    (lambda x: x.t(), "not contiguous"),
])
def test_fast_launch_names_the_argument_of_a_wrong_tensor(bad, why):
    a = torch.rand(3, 3)
    with pytest.raises(ValueError, match=f"'p.a'.*{why}"):
        fast_launch(_axpy, (3, 3), "cpu", None, (bad(a), 1.0), torch.rand(3, 3), 0, torch.zeros(3, 3))
    with pytest.raises(TypeError, match="takes 4 arguments"):
        fast_launch(_axpy, (3, 3), "cpu", None, (a, 1.0), torch.rand(3, 3))


def test_launch_parts_cover_every_thread_once_on_one_core_and_on_two(monkeypatch):
    x = torch.rand(1001)
    want = torch.zeros(1001)
    Launcher.of(_strided, "cpu")(1001, None, x, want, 0, 1)
    for cores in (1, 2):
        monkeypatch.setattr(W, "cpu_cores", lambda: cores)
        for n_parts in (2, 3):
            got = torch.full((1001,), float("nan"))
            launch_parts(_strided, 1001, "cpu", n_parts, lambda p: (x, got))
            assert torch.equal(got, want), (cores, n_parts)


def test_cpu_compositing_gives_the_same_numbers_on_one_core_and_two(monkeypatch):
    """The CPU's compositing parts (render.CPU_PARTS) run on threads where there are cores; the image and
    every gradient must not depend on it, bit for bit."""
    from test_rasterizer import make_scene, run_warp

    scene = make_scene(n=300, width=37, height=21, seed=3, scale_range=(0.05, 0.3), spread=0.9)
    w = torch.rand(21, 37, 3, generator=torch.Generator().manual_seed(4))

    def render():
        out, ins = run_warp(scene, "cpu", grad=True)
        ((out.image * w).sum() + 0.1 * out.depth.sum() + 0.3 * out.alpha.sum()).backward()
        return out, {k: v.grad.clone() for k, v in ins.items()}

    results = []
    for cores in (1, 2):
        monkeypatch.setattr(W, "cpu_cores", lambda: cores)
        results.append(render())
    (o1, g1), (o2, g2) = results
    for name in ("image", "depth", "alpha"):
        assert torch.equal(getattr(o1, name), getattr(o2, name)), name
    assert g1.keys() == g2.keys() and all(torch.equal(g1[k], g2[k]) for k in g1)
    assert all(float(g.abs().sum()) > 0 for g in g1.values())


def test_launch_parts_work_in_a_forked_child_after_the_parent_used_its_threads(monkeypatch):
    """A process forked after the parent ran parts on its thread pool has none of those threads: the child
    must make its own pool rather than wait forever on the parent's."""
    import multiprocessing as mp

    monkeypatch.setattr(W, "cpu_cores", lambda: 2)
    x = torch.rand(301)
    got = torch.zeros(301)
    launch_parts(_strided, 301, "cpu", 2, lambda p: (x, got))  # the parent's pool now exists
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    proc = ctx.Process(target=_child_parts, args=(x, q))
    proc.start()
    proc.join(timeout=60)
    alive = proc.is_alive()
    if alive:
        proc.kill()
    assert not alive, "the forked child hung on its parent's thread pool"
    assert q.get(timeout=5) == got.tolist()


def _child_parts(x, q):
    W.cpu_cores = lambda: 2
    out = torch.zeros(301)
    launch_parts(_strided, 301, "cpu", 2, lambda p: (x, out))
    q.put(out.tolist())


def test_threads_launching_one_kernel_at_once_each_get_their_own_arguments():
    """Launchers are per thread: two threads launching the same kernel with different tensors and numbers at
    the same time (a viewer serving two clients) must each get exactly their own result."""
    import threading

    g = torch.Generator().manual_seed(5)
    inputs = [(torch.rand(6, 3, generator=g), torch.rand(6, 3, generator=g), float(k), k) for k in range(2)]
    wrong = []

    def work(a, x, scale, shift):
        want = scale * x + a + shift
        for _ in range(300):
            out = torch.zeros(6, 3)
            fast_launch(_axpy, (6, 3), "cpu", None, (a, scale), x, shift, out)
            if not torch.equal(out, want):
                wrong.append(shift)
                return

    import sys

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads between almost any two bytecodes: races show up
    try:
        threads = [threading.Thread(target=work, args=args) for args in inputs]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    assert not wrong
    assert Launcher.of(_axpy, "cpu") is Launcher.of(_axpy, "cpu")  # one per thread, reused


# ----------------------------------------------------------------------------------------------------
# the host path's shortcuts: device names cached, raw stream handles, the direct CUDA launch and the native
# stream scope (their CUDA halves are checked here against stand-ins for Warp's native functions; the GPU
# tests run them for real)


def test_device_of_names_cpu_once_and_rejects_other_devices():
    assert W.device_of(torch.zeros(2)) == "cpu"
    assert W._DEVICE_NAMES[torch.device("cpu")] == "cpu"  # looked up once, then read from the table
    with pytest.raises(ValueError, match="cpu or cuda"):
        W.device_of(torch.zeros(2, device="meta"))
    assert torch.device("meta") not in W._DEVICE_NAMES


def test_launch_stream_is_none_on_the_cpu():
    assert W.launch_stream(torch.zeros(2)) is None


def test_cpu_launcher_takes_none_and_leaves_any_other_stream_to_warp():
    """A CPU launch ignores its stream as Warp's does: None, or whatever a caller hands it (a handle, an object)."""
    a, x = torch.rand(4, 3), torch.rand(4, 3)
    want = 2.0 * x + a + 1
    for stream in (None, 12345, object()):
        got = torch.zeros(4, 3)
        fast_launch(_axpy, (4, 3), "cpu", stream, (a, 2.0), x, 1, got)
        assert torch.equal(got, want)


class _Recorder:
    def __init__(self):
        self.calls = []


def test_a_cuda_launcher_given_a_handle_calls_the_native_launch_with_the_current_size(monkeypatch):
    """The direct route of ``Launcher.__call__`` (a CUDA launcher given a raw handle), with the native launch
    replaced: it gets the launch's thread count after every change of dim and the handle as it is; while a Warp
    graph capture is under way the launch goes through ``wp.Launch.launch`` with the handle wrapped instead."""
    launcher = W.Launcher(_axpy, "cpu")  # a launcher of its own: its fields are changed below
    rec = _Recorder()
    runtime = type("Runtime", (), {"captures": {}})()
    launcher.is_cuda, launcher._runtime = True, runtime
    launcher._native = lambda size, stream: rec.calls.append(("native", size, stream))
    launcher.cmd.launch = lambda stream=None: rec.calls.append(("warp", stream))
    monkeypatch.setattr(W, "wp_stream", lambda device, stream: ("wrapped", device, stream))
    a, x, out = torch.rand(5, 3), torch.rand(5, 3), torch.zeros(5, 3)
    launcher((5, 3), 77, (a, 1.0), x, 0, out)
    launcher((5, 3), 78, (a, 1.0), x, 0, out)
    launcher((2, 3), 79, (a[:2], 1.0), x[:2], 0, out[:2])
    launcher((0, 3), 80, (a[:0], 1.0), x[:0], 0, out[:0])  # no threads: nothing launched
    runtime.captures[1] = object()
    launcher((4, 3), 81, (a[:4], 1.0), x[:4], 0, out[:4])
    launcher((4, 3), None, (a[:4], 1.0), x[:4], 0, out[:4])  # None / a wp.Stream: Warp's own route
    assert rec.calls == [("native", 15, 77), ("native", 15, 78), ("native", 6, 79),
                         ("warp", ("wrapped", "cpu", 81)), ("warp", None)]
    assert launcher.cmd.bounds.size == 12


def test_native_launch_passes_warps_launch_fields_and_raises_warps_error():
    from types import SimpleNamespace

    hooks = SimpleNamespace(forward="FN", forward_smem_bytes=48, forward_smem_shortfall=None)
    cmd = SimpleNamespace(device=SimpleNamespace(context="CTX"), hooks=hooks, max_blocks=0, block_dim=256,
                          grid_stride=True, cluster_dim=1, params_addr="PARAMS", kernel=SimpleNamespace(key="k"))
    calls, result = [], [0]

    def launch_kernel(*args):
        calls.append(args)
        return result[0]

    go = W._native_launch(cmd, launch_kernel)
    go(1000, 5)
    assert calls == [("CTX", "FN", 1000, 0, 256, 1, 1, 48, "PARAMS", 5, None)]
    result[0] = 1  # a failed launch raises Warp's error (here its shared-memory message, which needs no runtime)
    hooks.forward_smem_shortfall = "more than the device has"
    with pytest.raises(RuntimeError, match="Error launching kernel: k"):
        go(10, 5)


class _FakeCore:
    """Warp's native context and stream functions, recording their calls."""

    def __init__(self, log):
        self.log = log

    def wp_cuda_context_push_current(self, ctx):
        self.log.append(("push", ctx))

    def wp_cuda_context_pop_current(self):
        self.log.append(("pop",))

    def wp_cuda_context_get_stream(self, ctx):
        self.log.append(("get", ctx))
        return 1111

    def wp_cuda_context_set_stream(self, ctx, stream, sync):
        self.log.append(("set", ctx, stream, sync))


def test_native_on_stream_sets_the_stream_without_a_wait_and_restores_it(monkeypatch):
    log = []
    runtime = type("Runtime", (), {"captures": {}, "core": _FakeCore(log)})()
    monkeypatch.setattr(W, "_native_runtime", lambda: runtime)
    monkeypatch.setattr(W, "_cuda_context", lambda device: ("CTX", device))
    ctx = ("CTX", "cuda:3")
    assert W.native_on_stream("cuda:3", 42, lambda *a: log.append(("fn",) + a), 1, 2)
    assert log == [("push", ctx), ("get", ctx), ("set", ctx, 42, 0), ("fn", 1, 2), ("set", ctx, 1111, 0), ("pop",)]

    log.clear()

    def boom(*a):
        raise KeyError("sort failed")

    with pytest.raises(KeyError):
        W.native_on_stream("cuda:3", 42, boom)
    assert log == [("push", ctx), ("get", ctx), ("set", ctx, 42, 0), ("set", ctx, 1111, 0), ("pop",)]

    log.clear()
    assert not W.native_on_stream("cuda:3", None, boom)  # a wp.Stream or None: the caller's ScopedStream
    runtime.captures[1] = object()
    assert not W.native_on_stream("cuda:3", 42, boom)  # a Warp capture under way: likewise
    assert log == []
