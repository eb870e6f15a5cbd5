"""``python -m ringscan ARGS``: the ringscan command line, run from the extension."""

import signal
import sys

from ._ringscan import cli_main


def main() -> int:
    # The command line runs without the GIL and never returns to the interpreter, so
    # Python's SIGINT handler (which only sets a flag for the interpreter to check) would
    # swallow Ctrl-C. The default action ends the process as the `ringscan` binary does;
    # `listen` installs its own handler over it and still finishes its file.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    return cli_main(["ringscan", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
