"""``python -m drillcosim ...``: the ``drillcosim`` command (:func:`drillcosim.cosim.cli.console_main`)."""

import sys

from drillcosim.cosim.cli import console_main

if __name__ == "__main__":
    sys.exit(console_main())
