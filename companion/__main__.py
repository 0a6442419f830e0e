"""``python -m companion`` is the ``companion`` command."""

import sys

from companion.launch import main

sys.exit(main())
