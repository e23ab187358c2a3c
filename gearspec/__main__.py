"""``python -m gearspec``: the command line (the same as the ``gearspec`` command)."""
from .cli import main

raise SystemExit(main())
