"""`python -m kinswarm.actors.cli`: the command line, as the `kinswarm` script runs it."""

import sys

from kinswarm.actors.cli.entry import main

sys.exit(main())
