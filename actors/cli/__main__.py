"""`python -m kinswarm.actors.cli`: the command line, as the `kinswarm` script runs it."""

import sys

from kinswarm.actors.cli.commands import main

sys.exit(main())
