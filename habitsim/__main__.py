import sys

from habitsim.cli import main

sys.exit(main())
