import sys

from pairplay.cli.main import main

sys.exit(main())
