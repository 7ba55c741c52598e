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
