"""``python -m robot``: the sonarslam command line."""

from robot.cli import main

raise SystemExit(main())
