"""``python -m dospcot_lab``: the same as ``dospcot-lab``."""

from dospcot_lab.cli import main

raise SystemExit(main())
