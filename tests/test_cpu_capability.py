"""``import warpgs`` asks torch for its AVX2 CPU kernels on x86 machines without CUDA (warpgs/__init__.py), so a
fixed-seed CPU run gives the same figures on AVX2 and AVX-512 machines; a capability the user sets is kept."""

import os
import platform
import subprocess
import sys

import pytest
import torch

X86 = platform.machine().lower() in ("x86_64", "amd64")


def capability(code: str, **env) -> str:
    e = {k: v for k, v in os.environ.items() if k != "ATEN_CPU_CAPABILITY"}
    e.update(env)
    out = subprocess.run([sys.executable, "-c", code + "; print(torch.backends.cpu.get_cpu_capability())"],
                         env=e, capture_output=True, text=True, timeout=120, check=True)
    return out.stdout.strip().splitlines()[-1]


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
