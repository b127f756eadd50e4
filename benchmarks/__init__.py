"""Speed and accuracy benchmarks; each writes results/bench/<name>.json (docs/results.md)."""
