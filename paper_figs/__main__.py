import sys

from .make_figs import main

sys.exit(main())
