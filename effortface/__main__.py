import sys

from effortface.cli import main

sys.exit(main())
