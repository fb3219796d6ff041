"""``python -m jaxparam.cli``: the ``jaxparam`` command."""
import sys

from . import main

sys.exit(main())
