"""The ``ramdaq`` command line and the commands that read recordings: analyze, gap, the gap
benchmark, info. Thin: they parse, call the acquisition and analysis, and print."""
