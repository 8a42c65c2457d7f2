#!/usr/bin/env bash
# Regenerate the golden corpus: record every tests/fixtures/golden/*.yaml with the current
# engine into the .mcap beside it (tests/test_golden_corpus.py replays them).
#
# Only after a deliberate physics change: bump isaac.engine.PHYSICS_VERSION, list the change in
# CHANGELOG.md, run this, and commit the new logs with the reason (docs/replay.md). Each log is
# the run's full length (the scene's world.steps); the corpus stays a few hundred kB.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
for scene in tests/fixtures/golden/*.yaml; do
    log=${scene%.yaml}.mcap
    rm -f "$log"
    "$PY" -m isaac run "$scene" --mcap "$log" --quiet >/dev/null
    printf '%-40s %7d bytes\n' "$log" "$(stat -c %s "$log")"
done
