"""``python -m gateway`` is ``drive-gateway``."""

from gateway.cli import main

raise SystemExit(main())
