"""Where things are, for tests in any folder under ``tests/``."""
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent
STAGES = ROOT / "stages"
REFERENCE = STAGES / "reference"
DATA = TESTS / "data"

#: Why the cross-checks against the eulumdat reader are skipped where it is missing.
NO_EULUMDAT = "the eulumdat cross-check reader (extra crosscheck) is not installed"
