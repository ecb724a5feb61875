"""The ``active-contacts`` command line.

One function per subcommand (``_cmd_<name>``), registered in :func:`parser`; every exit
code is in :data:`EXIT_CODES` (also shown by ``--help``): 0 met, 1 a stability case failed,
2 a user error (one line on stderr, nothing written), 3 finished but missed the request
(outputs written, one ``shortfall:`` line), 130 interrupted, 141 the reader stopped reading.
``--json`` prints machine-readable output on stdout. Outputs are all or nothing: the output
folder is checked before any work and replaced as a whole at the end."""

from ._common import EXIT_CODES
from ._main import main
from ._parser import parser

__all__ = ["main", "EXIT_CODES"]
