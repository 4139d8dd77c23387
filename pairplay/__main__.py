import sys

from pairplay.services.cli import main

sys.exit(main())
