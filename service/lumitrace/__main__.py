"""``python -m lumitrace``: the command line (signals caught while the package loaded
are handed to it, see :data:`lumitrace.EARLY_SIGNALS`)."""
import sys

from . import EARLY_SIGNALS
from .cli import main

sys.exit(main(early_signals=EARLY_SIGNALS))
