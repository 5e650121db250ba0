"""Allow ``python -m femstudy``."""

from femstudy.cli import main

raise SystemExit(main())
