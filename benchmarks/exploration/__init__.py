"""The exploration log behind named sections of BENCHMARKS.md: scripts kept as they led to a
finding, not maintained measurements (README.md says which script supports which finding).
Run as `python -m benchmarks.exploration.<name> [options]` from the repository's root."""
