"""Benchmarks behind ``make bench``: one module ``bench_<name>.py`` per area.

Each module has ``run(out_dir: pathlib.Path, quick: bool) -> dict`` that measures,
writes ``bench/results/<name>.json`` and PNG plots through :mod:`.report`, and updates its
own section of docs/results.md. Benchmarks are never part of ``make test``.
"""
