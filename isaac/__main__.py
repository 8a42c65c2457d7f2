import sys

from isaac.cli import main

sys.exit(main())
