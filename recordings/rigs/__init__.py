"""The shipped rigs (package data ``ramdaq.rigs``): ``--rig albacore`` finds ``albacore.toml`` here."""
