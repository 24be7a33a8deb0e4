"""Where things are, for tests in any folder under ``tests/``."""
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent
STAGES = ROOT / "stages"
REFERENCE = STAGES / "reference"
DATA = TESTS / "data"
