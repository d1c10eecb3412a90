import sys

from bayesmachine.cli import main

sys.exit(main())
