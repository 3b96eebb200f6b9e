import sys

from nonholo.cli import main

sys.exit(main())
