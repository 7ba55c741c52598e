import sys
from pathlib import Path

# tests/reference.py (the torch oracle) is imported by name from the test files.
sys.path.insert(0, str(Path(__file__).resolve().parent))
