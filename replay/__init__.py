"""Replay: re-simulate a log from its contents alone and compare it bit for bit with what was
logged, naming the first divergence (step, body, field, ULPs).

`reader` reads a log's raw messages step by step, `compare` replays and diffs logs, `report`
holds the verdict and its text and JSON forms.

May import: the engine, the scene contract, `recorder` (the log format it reads), `isaac.errors`
and the mcap library. Never the app.
"""
