import sys

from cgfem.cli import main

sys.exit(main())
