import sys

from paramlod.app.cli import main

sys.exit(main())
