"""`python -m parsph` is the `parsph` command."""

from parsph.cli import main

raise SystemExit(main())
