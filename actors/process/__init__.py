"""An actor's process (main.py): the one spawn path of the `process` placement, the zygote its actors are forked
from, and `build_actor`, shared with the `single` placement. Above every actor kind, below the supervisor."""
