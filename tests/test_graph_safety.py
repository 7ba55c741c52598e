"""Host reads in the step a CUDA graph records (``warpgs.engine.graphstep``), found on the CPU.

A CUDA graph's capture refuses any operation that hands the host a value of the device (``bool(t)``, ``.item()``,
``torch.nonzero``, indexing with a boolean mask, ...): the recording fails, the graphs are off for the run and every
step pays the host's launches again. The GPU test of the graphs (``test_graph_fallback.py``) sees that only on a GPU.
Here nothing is captured: ``StepGraph`` runs on the CPU with stand-ins for CUDA's streams and graphs, its recording
and each replay running the recorded body (``StepGraph._body``: ``forward_backward``, ``update_on_device``,
``densify``) eagerly under ``HostReads``, a dispatch mode that notes every aten operation that reads the device on
the host on CUDA, with the lines that called it.

``HostReads`` sees aten operations only: a ``.tolist()``, ``.cpu()`` or ``.numpy()`` (a copy, which is no aten
operation on the CPU's own tensors) and Warp's own host reads go unseen. Sorting, ``lift_fresh`` (a Python number
made a tensor) and medians read nothing on CUDA and are not noted.
"""

import collections
import contextlib
import traceback
import weakref
from pathlib import Path

import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

import warpgs.optim
from tiny_scene import full_method_trainer
from warpgs.engine.graphstep import StepGraph
from warpgs.engine.stepguard import SYNC_EVERY_CUDA

# aten operations whose CUDA kernels read a device value on the host, whatever their arguments
_READS = frozenset({
    "_local_scalar_dense",  # .item(), float(t), int(t), bool(t)
    "is_nonzero", "equal", "allclose",
    "nonzero", "masked_select",  # torch.nonzero, torch.where(cond), argwhere
    "unique", "_unique", "_unique2", "unique_dim", "unique_consecutive", "unique_dim_consecutive",
    "bincount",  # its size is the largest value
    "_linalg_check_errors",  # torch.linalg.inv / cholesky / solve: the info codes (the *_ex variants do not)
})
_MASKS = (torch.bool, torch.uint8)  # an index of these dtypes is a mask: its nonzero entries, read on the host
_ROOT = Path(__file__).resolve().parents[1]


class HostReads(TorchDispatchMode):
    """Notes each aten operation that reads a device value on the host on CUDA (``hits``: (its name, the
    project's lines that called it, innermost last))."""

    def __init__(self):
        super().__init__()
        self.hits: list[tuple[str, str]] = []
        self._numbers: dict[int, weakref.ref] = {}  # Python numbers made tensors (lift_fresh): on CUDA, on the host

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        name = func.overloadpacket.__name__.rstrip("_")
        if name == "lift_fresh":
            self._numbers = {k: r for k, r in self._numbers.items() if r() is not None}
            self._numbers[id(out)] = weakref.ref(out)
        elif self._reads(name, func, args, kwargs):
            self.hits.append((str(func), _project_stack()))
        return out

    def _reads(self, name: str, func, args, kwargs) -> bool:
        if name in _READS:
            return True
        if name == "repeat_interleave":  # the output's size is the repeats' sum unless given
            return any(isinstance(a, torch.Tensor) for a in args) and kwargs.get("output_size") is None \
                and func._overloadname != "self_int"
        if name == "histc":  # the range is the input's own when min == max
            lo, hi = (list(args[2:4]) + [kwargs.get("min", 0), kwargs.get("max", 0)])[:2]
            return lo == hi
        if name == "index":
            return any(isinstance(i, torch.Tensor) and i.dtype in _MASKS for i in args[1])
        if name in ("index_put", "_index_put_impl"):
            index = [i for i in args[1] if i is not None]
            if not any(i.dtype in _MASKS for i in index):
                return False
            # t[mask] = a Python number is masked_fill_ with a value on the host (``canDispatchToMaskedFill``)
            value, accumulate = args[2], (list(args[3:4]) + [kwargs.get("accumulate", False)])[0]
            number = self._numbers.get(id(value))
            return accumulate or len(index) > 1 or value.numel() != 1 or number is None or number() is not value
        return False


def _project_stack(depth: int = 8) -> str:
    """The calling lines in this repository (not torch's, nor ``HostReads``'), innermost last."""
    frames = [f for f in traceback.extract_stack()[:-3] if _ours(Path(f.filename).resolve())]
    return "".join(traceback.format_list(frames[-depth:]))


def _ours(path: Path) -> bool:
    return path.is_relative_to(_ROOT) and not path.relative_to(_ROOT).parts[0].startswith(".")  # not .venv's


def _report(hits) -> str:
    """Each distinct read once, with how many times it ran."""
    return "\n".join(f"--- {op} ({n}x)\n{stack}" for (op, stack), n in collections.Counter(hits).items())


@contextlib.contextmanager
def _cpu_graphs(monkeypatch, reads: HostReads):
    """``StepGraph`` on the CPU: its streams do nothing, and its graph's capture and each replay run the recorded
    body (``StepGraph._body``) eagerly under ``reads``. The capture is the step's own work (what the first replay
    does on CUDA), so the replay that follows it does nothing. Yields the counts of bodies run, all and those
    that render a pseudo view (``FullMethod.graph_inputs``)."""
    counts = {"bodies": 0, "pseudo": 0, "pools": []}
    recorded = {}
    alive = {}  # live graphs: serial -> their memory pool (as CUDA's, a pool lives while a graph uses it)

    class Stream:
        def wait_stream(self, other):
            pass

    class Graph:
        serial = 0

        def __init__(self):
            self.fresh = False
            Graph.serial += 1
            self.n, self._pool = Graph.serial, None
            weakref.finalize(self, alive.pop, self.n, None)

        def register_generator_state(self, generator):
            pass

        def pool(self):
            return self._pool

        def capture_begin(self, pool=None, capture_error_mode=None):
            # which pool each recording was given, and whether a live graph held it then
            counts["pools"].append((pool, pool is not None and pool in alive.values()))
            self._pool = pool if pool is not None else (0, self.n)
            alive[self.n] = self._pool
            reads.__enter__()
            self.fresh = True

        def capture_end(self):
            reads.__exit__(None, None, None)

        def replay(self):
            if self.fresh:
                self.fresh = False
                return
            sg, (cam, capacity) = recorded["graph"], recorded["body"]
            sg.tr.method.graph_bind(sg.extra)
            try:
                with reads:
                    sg.record = sg._body(cam, capacity)
            finally:
                sg.tr.method.graph_bind(None)

    real_body = StepGraph._body

    def body(self, cam, capacity):
        recorded["graph"], recorded["body"] = self, (cam, capacity)
        counts["bodies"] += 1
        counts["pseudo"] += "pseudo_image" in self.extra
        return real_body(self, cam, capacity)

    monkeypatch.setattr(StepGraph, "_body", body)
    monkeypatch.setattr(torch.cuda, "Stream", lambda *a, **k: Stream())
    monkeypatch.setattr(torch.cuda, "stream", lambda s: contextlib.nullcontext())
    monkeypatch.setattr(torch.cuda, "current_stream", lambda *a, **k: Stream())
    monkeypatch.setattr(torch.cuda, "CUDAGraph", Graph)
    yield counts


def test_the_full_methods_graph_steps_read_nothing_on_the_host(tmp_path, monkeypatch):
    """The full method's run of ``test_graph_fallback.py`` on the CPU, in 40 steps (both cycles: one input and one
    pseudo view a step, the stereo's depth priors, the binocular term, dropout), as on CUDA where it matters here
    (the verdicts read every ``SYNC_EVERY_CUDA`` steps, fused Adam) and with ``StepGraph`` run on the CPU
    (``_cpu_graphs``): the graphs stay on, the recorded body runs for more than ten steps, more than five of them
    with a pseudo view, and no aten operation in it reads a device value on the host (the pseudo view's render once
    did: ``render``'s ``_check_finite``, which voided every recording of the cycles' steps)."""
    # CUDA's Adam, fused (torch's default on the CPU reads its step counts on the host)
    monkeypatch.setattr(warpgs.optim, "adam_options", lambda device: {"fused": True})
    tr = full_method_trainer(tmp_path, "cpu", 40, "--set", f"guard.sync_every={SYNC_EVERY_CUDA}")
    reads = HostReads()
    with _cpu_graphs(monkeypatch, reads) as counts:
        tr.graph = StepGraph(tr)
        tr.run()
    g = tr.graph
    assert g is not None and g.off is None, g and g.off
    assert counts["bodies"] > 10 and counts["pseudo"] > 5, (counts, g.captures, g.replays)
    assert not reads.hits, f"host reads in the recorded step:\n{_report(reads.hits)}"
    # every recording after the first is made into the first one's memory pool, while the graph before it (which
    # holds the pool) is alive: a pool each would keep every dropped graph's memory reserved on the GPU
    first, *later = counts["pools"]
    assert first == (None, False) and len(later) >= 2 and g.captures == len(later) + 1, counts["pools"]
    assert {pool for pool, _ in later} == {g.graph.pool()} and all(held for _, held in later), counts["pools"]


@pytest.mark.parametrize("read", ["bool", "mask", "where", "item", "repeat"])
def test_host_reads_finds_a_host_read(read):
    """``HostReads`` notes a read of the device (a tensor's truth, a boolean mask's indexing and assignment,
    ``torch.where`` of a condition, ``.item()``, ``repeat_interleave`` without its output's size), with the line
    that made it, and not what reads nothing on CUDA (a Python number assigned through a mask, a sort, a median,
    ``repeat_interleave`` given its size)."""
    t = torch.arange(6.0)
    reads = HostReads()
    with reads:
        t[t > 4] = 0.0
        torch.sort(t), t.nanmedian(), t.median()
        torch.repeat_interleave(t, torch.ones(6, dtype=torch.long), output_size=6)
        assert not reads.hits, _report(reads.hits)
        if read == "bool":
            bool(t.any())
        elif read == "mask":
            t[t > 2] = torch.ones(())
            t[t > 2]
        elif read == "where":
            torch.where(t > 2)
        elif read == "item":
            t.sum().item()
        else:
            torch.repeat_interleave(t, torch.ones(6, dtype=torch.long))
    assert reads.hits
    assert all(Path(__file__).name in stack for _, stack in reads.hits), _report(reads.hits)
    if read == "mask":
        assert [op for op, _ in reads.hits] == ["aten.index_put_.default", "aten.index.Tensor"]
