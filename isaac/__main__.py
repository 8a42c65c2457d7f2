import sys

from isaac.app.cli import main

sys.exit(main())
