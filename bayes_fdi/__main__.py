"""``python -m bayes_fdi`` runs the command line."""

import sys

from bayes_fdi.cli import main

sys.exit(main())
