"""Research, not product: the configurations and probes that found what the product recommends, kept runnable so
that every number in docs/notebook/ can be made again. Nothing in actors/, sim/ or protocol/ imports this, and
`kinswarm experiment` does not list it.

    python -m kinswarm.experiments.research corridor_studies --quick --out runs/research
    python -m kinswarm.experiments.research successive_training --out runs/research   # ~13 min on 2 cores
    python -m kinswarm.experiments.research beat_the_rule --out runs/full   # shares the generalisation runs
    python -m kinswarm.experiments.research grasp_epsilon_decay --out runs/research   # ~6 min on 2 cores
    python -m kinswarm.experiments.research grasp_anneal --seeds 5 --out runs/research   # ~15 min on 2 cores
    python -m kinswarm.experiments.research fleet_generalise --out runs/full   # fleets on §5.2's protocol; ~25 min
    python -m kinswarm.experiments.research fleet_reach3d --out runs/full   # a fleet training the iiwa; ~5 min
    python -m kinswarm.experiments.research sensed_tip3d --out runs/research   # the iiwa's encoder offsets; ~5 min

Each module has a `run(ctx)` like the experiments' (experiments/common.py `Context`); options of the learner or
the tasks that were measured and not kept are deleted from the code, so the configurations that used them are
gone from here too (their numbers stay in docs/notebook/ and the committed reports).
"""
