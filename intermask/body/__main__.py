"""``python -m intermask.body SAMPLE... --body-model PATH``: see intermask.body.command."""

import sys

from intermask.body.command import main

sys.exit(main())
