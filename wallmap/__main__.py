"""``python -m wallmap``: the same as the ``wallmap`` command."""

import sys

from wallmap.cli import main

sys.exit(main())
