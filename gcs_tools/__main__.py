from gcs_tools.cli import main

raise SystemExit(main())
