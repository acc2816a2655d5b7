"""The benchmark suite: `python -m bench NAME [ARGS]` (`make bench NAME=... ARGS=...`); each
benchmark writes bench/results/NAME.json in one schema (bench/common.py)."""
