"""The application: the `isaac` command line and the tools built on the engine.

- `cli`: the parser and `main` (every `IsaacError` becomes one line and an exit status).
- `run`: `isaac run` and `isaac check`; `logs`: `inspect`, `recover`, `view`; `verify`:
  `replay` and `diff`; `tradeoff`: the measured speed/accuracy trade; `profile`: per-stage
  timings for `isaac run --profile`.

May import everything: the engine, the scene contract, `recorder` and `replay`. Nothing imports
the app.
"""
