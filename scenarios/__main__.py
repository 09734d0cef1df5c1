"""``python -m scenarios`` is ``mapupdate``, as the project's command line was first named."""

from mapupdate import main

raise SystemExit(main())
