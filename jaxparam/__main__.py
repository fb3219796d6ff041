"""``python -m jaxparam``: the ``jaxparam`` command (as ``python -m jaxparam.cli``)."""
import sys

from .cli import main

sys.exit(main())
