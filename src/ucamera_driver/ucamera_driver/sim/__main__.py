"""``python -m ucamera_driver.sim``: the ucamera_sim command line."""

from .cli import main

raise SystemExit(main())
