"""`python -m server.cli`: the `srlab` command without its console script."""

from server.cli import main

raise SystemExit(main())
