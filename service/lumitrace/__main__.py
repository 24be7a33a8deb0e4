"""``python -m lumitrace``: the command line (signals caught while the package loaded
are handed to it, see :data:`lumitrace.EARLY_SIGNALS`)."""
import sys

from . import EARLY_SIGNALS
from .cli import main
from .quick_exit import finish

sys.exit(finish(main(early_signals=EARLY_SIGNALS)))
