"""``python -m capture_driver.sim``: the capture_sim command line."""

from .cli import main

raise SystemExit(main())
