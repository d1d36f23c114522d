import sys

from doefab.cli import main

sys.exit(main())
