"""The reproduction of Du, Lin & Mordatch (CoRL 2019) on the harness: its experiments, cells and figures, the paper's
numbers and claims, the records of finished runs and ``docs/results.md``.

The harness (``eval``) knows no paper; this package is one user of it. ``ebm-eval --experiment NAME`` runs its parts.
"""
