"""Speed benchmarks of the library, apart from the evaluation harness.

- ``python -m benchmarks`` (``make bench``, :mod:`benchmarks.cli`): plan time next to pytorch-mppi
  (:mod:`benchmarks.planner`), the roofline of this host (:mod:`benchmarks.roofline`) and ``learn`` time against
  PPO (:mod:`benchmarks.learn`).
- ``python -m benchmarks.envs`` (``make bench-envs``): throughput of every registered environment.
"""
