"""The pkwbus benchmarks (bench/README.md): each a module run from the repository's root,
``python -m bench.NAME``; ``python -m bench.run_all`` runs them all (``make bench``)."""
