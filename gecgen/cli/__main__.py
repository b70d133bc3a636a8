"""`python -m gecgen.cli`: the same as the `gecgen` command."""
import sys

from gecgen.cli import main

sys.exit(main())
