import sys

from holder_cad.cli import main

sys.exit(main())
