"""``python -m toolkit.cli``: the ``active-contacts`` command line."""

from ._main import main

raise SystemExit(main())
