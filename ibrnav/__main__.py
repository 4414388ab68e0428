import sys

from ibrnav.cli import main

sys.exit(main())
