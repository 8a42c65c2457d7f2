"""`python -m bench`: the benchmark suite (see bench/suite.py), then the loaded-machine recording
measurement (bench/loaded.py) unless `--no-loaded` or `--quick`, then Box2D v3's joint grid
against pymunk (bench/joint_grid.py) and the shipped chain and Newton's cradle against pymunk
(bench/joint_scenes.py) unless `--no-joint-grid` or `--quick`."""

import argparse
import sys

from bench.suite import RESULTS, main

NO_LOADED_HELP = (
    "  --no-loaded           skip the recording measurement beside two busy-loop processes "
    "(bench/loaded.py, about 2 min)\n"
    "  --no-joint-grid       skip the 100 x 100 joint grid, the chain and the cradle against "
    "pymunk (bench/joint_grid.py, bench/joint_scenes.py, about 2 min)"
)

argv = sys.argv[1:]
no_loaded = "--no-loaded" in argv
no_joint_grid = "--no-joint-grid" in argv
argv = [a for a in argv if a not in ("--no-loaded", "--no-joint-grid")]
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
if rc == 0 and not no_joint_grid and "--quick" not in argv:
    from bench import joint_grid

    rc = joint_grid.main([])
    if rc == 0:
        from bench import joint_scenes

        rc = joint_scenes.main([])
sys.exit(rc)
