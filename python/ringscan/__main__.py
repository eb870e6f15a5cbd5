"""``python -m ringscan ARGS``: the ringscan command line, run from the extension."""

import sys

from ._ringscan import cli_main


def main() -> int:
    return cli_main(["ringscan", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
