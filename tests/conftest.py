import sys
from pathlib import Path

# tests/reference.py (the torch oracle) is imported by name from the test files.
sys.path.insert(0, str(Path(__file__).resolve().parent))

import torch

# Small tensors on a shared 2-core machine: torch's intra-op threads only add contention
# (Warp's CPU kernels run on one thread anyway).
torch.set_num_threads(1)
