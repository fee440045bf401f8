"""``python -m teleop``: the ``defgrasp-teleop`` collection app (see ``teleop.app.cli``)."""

from teleop.app.cli import main

raise SystemExit(main())
