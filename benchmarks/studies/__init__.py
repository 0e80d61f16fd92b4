"""One-off studies: each answered one question once (its report in benchmarks/out/ says what it
found); kept runnable, ``python -m benchmarks.studies.NAME``, not re-run as standing measurements.
"""
