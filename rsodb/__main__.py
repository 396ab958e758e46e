import sys

from rsodb.cli import main

sys.exit(main())
