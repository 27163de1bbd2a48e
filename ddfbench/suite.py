"""`python -m ddfbench.suite`: run, plan and check a suite of experiments (ddfbench.report.suite)."""

import sys

from ddfbench.report.suite import main

if __name__ == "__main__":
    sys.exit(main())
