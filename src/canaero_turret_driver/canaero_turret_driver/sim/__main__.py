"""``python -m canaero_turret_driver.sim``: the canaero_turret_sim command line."""

from .cli import main

raise SystemExit(main())
