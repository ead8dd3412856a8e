"""`python -m mexgen_gcs` runs the `mexgen-gcs` command line."""

from mexgen_gcs.cli import main

raise SystemExit(main())
