"""``python -m benchmarks``: the planner and learn-time benchmarks (see :mod:`benchmarks.cli`)."""

from benchmarks.cli import main

if __name__ == "__main__":
    main()
