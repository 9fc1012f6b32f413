from dospcot.cli import main

raise SystemExit(main())
