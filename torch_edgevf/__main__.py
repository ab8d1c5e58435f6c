"""``python -m torch_edgevf``: the ``edgevf`` command line; without arguments, the demo."""

import sys

from .cli import main

sys.exit(main(sys.argv[1:] or ["demo"]))
