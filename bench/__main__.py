"""`python -m bench`: the benchmark suite (see bench/suite.py), then the loaded-machine recording
measurement (bench/loaded.py) unless `--no-loaded` or `--quick`."""

import argparse
import sys

from bench.suite import RESULTS, main

NO_LOADED_HELP = (
    "  --no-loaded           skip the recording measurement beside two busy-loop processes "
    "(bench/loaded.py, about 2 min)"
)

argv = sys.argv[1:]
no_loaded = "--no-loaded" in argv
argv = [a for a in argv if a != "--no-loaded"]
if "-h" in argv or "--help" in argv:
    try:
        main(argv)
    except SystemExit:
        pass
    print(NO_LOADED_HELP)
    sys.exit(0)
rc = main(argv)
if rc == 0 and not no_loaded and "--quick" not in argv:
    from bench import loaded

    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--out", default=str(RESULTS))
    rc = loaded.main(["--out", parser.parse_known_args(argv)[0].out])
sys.exit(rc)
