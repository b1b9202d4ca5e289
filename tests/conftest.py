import os
import sys
from pathlib import Path

os.environ.setdefault("LANCE_LOG", "error")
# tests/public_layout.py is a helper module shared by several test files.
sys.path.insert(0, str(Path(__file__).parent))
