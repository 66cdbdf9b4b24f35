"""Benchmark programs: each is run as a module from the repository's root,
`python -m benchmarks.<name> [options]` (`--help` lists the options), prints what it measured
and writes it as JSON (`--out`, default under `benchmarks/results/`). BENCHMARKS.md quotes
each command beside its output. `benchmarks.exploration` holds the exploration scripts behind
some of its findings, kept as such."""
