"""ISAAC's benchmark suite against pymunk and Box2D: `python -m bench` (`make bench`).

scenes.py defines every scene once; peers/ builds it in each engine; worker.py runs one
(scene, engine) repetition in its own process; quality.py measures every engine's result with
the same code; suite.py interleaves, aggregates and writes bench/results/latest.{jsonl,md}.
"""
