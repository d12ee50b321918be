"""``python -m stages.viewer`` = ``livescene view``."""

from .cli import main

raise SystemExit(main())
