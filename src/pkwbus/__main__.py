from pkwbus.cli import main

raise SystemExit(main())
