"""``python -m rsodb.samples --out data_samples [--seed N]``: regenerate the bundled samples."""

import sys

from rsodb.samples.generate import main

sys.exit(main())
