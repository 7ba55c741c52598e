"""``import warpgs`` asks torch for its AVX2 CPU kernels and MKL for its reproducible branch on x86 machines without
CUDA (warpgs/__init__.py), so a fixed-seed CPU run gives the same figures on AVX2 and AVX-512 machines, Intel's and
AMD's; a capability or branch the user sets is kept."""

import os
import platform
import subprocess
import sys

import pytest
import torch

X86 = platform.machine().lower() in ("x86_64", "amd64")


def last_line(code: str, unset: tuple[str, ...], **env) -> str:
    """The last line ``code`` prints in a new interpreter, without the variables ``unset`` and with ``env``."""
    e = {k: v for k, v in os.environ.items() if k not in unset}
    e.update(env)
    out = subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True, timeout=120, check=True)
    return out.stdout.strip().splitlines()[-1]


def capability(code: str, **env) -> str:
    return last_line(code + "; print(torch.backends.cpu.get_cpu_capability())", ("ATEN_CPU_CAPABILITY",), **env)


@pytest.mark.skipif(not X86, reason="the AVX levels are x86's")
@pytest.mark.skipif(torch.cuda.is_available(), reason="GPU machines keep torch's own choice")
def test_warpgs_asks_for_avx2_kernels_and_keeps_a_users_choice():
    own = capability("import torch")  # what torch picks by itself on this CPU
    if own not in ("AVX2", "AVX512"):
        pytest.skip(f"this CPU has neither AVX2 nor AVX-512 kernels in torch ({own})")
    assert capability("import warpgs, torch") == "AVX2"
    assert capability("import torch, warpgs") == "AVX2"  # torch imported first, nothing dispatched yet
    assert capability("import warpgs, torch", ATEN_CPU_CAPABILITY="default") == "DEFAULT"
    assert capability("import warpgs, torch", ATEN_CPU_CAPABILITY=own.lower()) == own


PRODUCTS = ("import hashlib; g = torch.Generator().manual_seed(0); "
            "p = torch.rand(300, 3, generator=g) * 10; a = torch.rand(64, 257, generator=g); "
            "b = torch.rand(257, 64, generator=g, dtype=torch.float64); "
            "out = [torch.cdist(p, p), a @ a.T, b.T @ b]; "  # cdist of > 25 rows goes through a matrix product
            "print(hashlib.md5(b''.join(t.numpy().tobytes() for t in out)).hexdigest())")


def products(code: str, **env) -> str:
    return last_line(code + "; " + PRODUCTS, ("MKL_CBWR", "MKL_ENABLE_INSTRUCTIONS"), **env)


@pytest.mark.skipif(not X86, reason="MKL's kernels are picked among x86 instruction sets")
@pytest.mark.skipif(torch.cuda.is_available(), reason="GPU machines keep torch's own choice")
def test_warpgs_asks_mkl_for_the_same_products_on_every_x86_processor():
    """MKL's kernels for SSE4.2 and for this machine's widest instruction set (AVX2, AVX-512) round differently;
    after ``import warpgs`` (MKL_CBWR=COMPATIBLE) both give the same bits, as another processor then does."""
    if not torch.backends.mkl.is_available():
        pytest.skip("this torch has no MKL")
    # (on a processor where MKL's own SSE4.2 and widest kernels already agree the assertions hold trivially;
    # where they differ, only the reproducible branch makes them agree)
    branch = "import warpgs, os; print(os.environ.get('MKL_CBWR'))"
    assert last_line(branch, ("MKL_CBWR",)) == "COMPATIBLE"  # asked for before MKL's first call
    assert last_line(branch, ("MKL_CBWR",), MKL_CBWR="AUTO") == "AUTO"  # a user's branch is kept
    widest = products("import warpgs, torch")
    assert products("import warpgs, torch", MKL_ENABLE_INSTRUCTIONS="SSE4_2") == widest
    assert products("import torch, warpgs", MKL_ENABLE_INSTRUCTIONS="SSE4_2") == widest  # torch first, nothing run yet
