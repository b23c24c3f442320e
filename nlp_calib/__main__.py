"""``python -m nlp_calib``: the same as the ``nlp-calib`` command."""

from nlp_calib.cli import main

raise SystemExit(main())
