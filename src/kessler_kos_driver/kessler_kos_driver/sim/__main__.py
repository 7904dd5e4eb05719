"""``python -m kessler_kos_driver.sim``: the kessler_kos_sim command line."""

from .cli import main

raise SystemExit(main())
